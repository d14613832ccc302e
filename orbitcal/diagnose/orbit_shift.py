"""An element set's along-track error too large for the field's gradient.

The orbit error's forms (:func:`orbitcal.diagnose.design._design_orbit`) write the field change
of a position error to first order, ``db = ds dB/ds``: good to a nanotesla for tens of km. An
element set of a low, manoeuvring spacecraft a few days old can be hundreds of km off (the real
ISS element sets of ``tests/authorities`` 2-8 days apart: 4 of 12 pairs more than 100 km, 1,650
km at most), and there the second-order term (``ds^2 / 2 d2B/ds2``, ~65 nT at 450 km for a
30,000 nT field that turns over ~6,800 km of arc) is far above the noise: the first-order form's
misfit went into its radial and cross-track terms, beyond their ranges, and an independent world
with an element set 448 km behind had its orbit error refused as implausible (seed 10100
world 5: held-out residual 2,281 nT left unexplained).

So when the first-order form (``rtn``) puts the spacecraft more than :data:`SHIFT_MIN_KM` along
the track from where the element set says on the training samples, the design adds a form
linearised there (``rtn_shifted``): the positions moved along the orbit's arc by ``s0`` (a
rotation about the orbit normal), the along-track column the secant ``(B(s0) - B(0)) / s0`` (its
coefficient, ``along_track_km``, is then the offset itself, exact at ``s0``) and the other
columns the gradients at the moved positions. ``s0`` is refined by Gauss-Newton steps: the form
refitted on the training samples with the calibration (a dense least-squares fit of at most
:data:`SHIFT_FIT_SAMPLES` samples) until the offset moves by less than :data:`SHIFT_TOL_KM`.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.calibration_columns import calibration_rows
from orbitcal.diagnose.columns import ScaledVectorColumns
from orbitcal.diagnose.data import (
    EARTH_ROTATION_RAD_S,
    FIELD_SCALE_NT,
    DiagnosisData,
    _time_derivative,
)

__all__ = ["SHIFT_MIN_KM", "along_track_offset_km", "shifted_columns"]

#: Along-track offsets below this are left to the first-order forms [km]: the second-order term
#: is then below ~1 nT.
SHIFT_MIN_KM = 50.0
#: Gauss-Newton steps stop when the offset moves by less than this [km].
SHIFT_TOL_KM = 0.5
#: At most this many Gauss-Newton steps.
SHIFT_MAX_STEPS = 4
#: Training samples (evenly thinned) of the dense fits that estimate the offset.
SHIFT_FIT_SAMPLES = 3000


def moved_along_arc(data: DiagnosisData, s_km: float) -> tuple[FloatArray, FloatArray]:
    """Positions ``s_km`` further along the orbit at the same time, and their frame (radial,
    along-track, normal), ITRS, (N, 3) and (N, 3, 3): a rotation about the orbit normal by ``s /
    |r|``, at the radius the track reaches ``s / |v|`` later (to second order in that time:
    eccentricity and the oblate Earth's short-period terms change the radius by ~0.6 km over
    400 km of arc, 11 nT of the radial gradient)."""
    r = data.r_itrs_km
    t = data.t_utc_s
    frame = data.orbit_frame_itrs
    radial, along, normal = frame[:, :, 0], frame[:, :, 1], frame[:, :, 2]
    radius = np.linalg.norm(r, axis=1)
    omega = np.array([0.0, 0.0, EARTH_ROTATION_RAD_S])
    speed = np.linalg.norm(_time_derivative(t, r) + np.cross(omega, r), axis=1)
    dt_s = s_km / np.maximum(speed, 1e-9)
    rate = _time_derivative(t, radius)
    moved_radius = radius + rate * dt_s + 0.5 * _time_derivative(t, rate) * dt_s**2
    phi = (s_km / radius)[:, None]
    c, s = np.cos(phi), np.sin(phi)
    moved = moved_radius[:, None] * (c * radial + s * along)
    frame_moved = np.stack([c * radial + s * along, c * along - s * radial, normal], axis=2)
    return moved, frame_moved


def shifted_columns(
    data: DiagnosisData, s0_km: float, tau_days: FloatArray, a: FloatArray | None = None
) -> ScaledVectorColumns:
    """The ``rtn`` form's columns linearised at an along-track offset ``s0_km``: the secant of
    the field along the arc from the element set's position to ``s0_km`` beyond it, then the
    gradients at the moved positions (same order and scalars as ``rtn``'s, ``tau_days`` its
    time scalar), seen through the sensor's matrix ``a`` if given."""
    moved, frame = moved_along_arc(data, s0_km)
    field_fn = data.reference_field_fn
    b_moved_itrs = np.asarray(field_fn(data.t_utc_s, moved))
    b_moved = np.einsum("nij,nj->ni", data.rot_itrs_to_body, b_moved_itrs)
    secant = (b_moved - data.b_ref_body_nt) / s0_km
    grads = data.gradients_at(moved, frame)
    tau = tau_days
    u = data.orbit_phase_rad
    c, sn = np.cos(u), np.sin(u)
    grad, rad, nrm = grads[:, :, 1], grads[:, :, 0], grads[:, :, 2]
    if a is not None:
        secant, grad, rad, nrm = (np.einsum("ij,nj->ni", a, v) for v in (secant, grad, rad, nrm))
    return ScaledVectorColumns(
        data.n,
        [secant, grad, grad, grad, rad, rad, rad, nrm, nrm],
        [None, tau, c, sn, None, c, sn, c, sn],
    )


def along_track_offset_km(
    data: DiagnosisData, train: BoolArray, first_order: ScaledVectorColumns, tau_days: FloatArray
) -> tuple[float, FloatArray] | None:
    """The along-track offset ``s0`` [km] at which to linearise the orbit error and the
    sensor's matrix fitted with it (None when the first-order form's own, ``first_order``'s
    first coefficient, is below :data:`SHIFT_MIN_KM`): Gauss-Newton (secant) steps of
    :func:`shifted_columns` fitted on the training samples, seen through the sensor's matrix of
    the previous step.

    A field outside the instrument reaches its output as ``A b``. The joint fit adds the
    effects after the calibration, which for fields of tens of nT costs ``A``'s error of them
    (1-3 %): for a 400 km offset's 4,400 nT it left 58 nT unexplained (and the offset 2 %
    short), so the form is built through the matrix found here
    (:attr:`orbitcal.diagnose.design.DesignBlock.sensor_matrix`)."""
    s0, a = _fitted(data, train, first_order, None)
    if not (np.isfinite(s0) and abs(s0) >= SHIFT_MIN_KM):
        return None
    for _ in range(SHIFT_MAX_STEPS):
        s1, a = _fitted(data, train, shifted_columns(data, s0, tau_days), a)
        if not np.isfinite(s1) or abs(s1) < SHIFT_MIN_KM:
            return None
        done = abs(s1 - s0) < SHIFT_TOL_KM
        s0 = s1
        if done:
            break
    return s0, a


def _fitted(
    data: DiagnosisData,
    train: BoolArray,
    columns: ScaledVectorColumns,
    a: FloatArray | None,
) -> tuple[float, FloatArray]:
    """The first coefficient of ``columns`` (seen through the matrix ``a`` if given) fitted with
    the 12 calibration parameters on (at most :data:`SHIFT_FIT_SAMPLES` of) the training
    samples by dense least squares, and the fitted matrix."""
    index = np.flatnonzero(train)
    if index.size > SHIFT_FIT_SAMPLES:
        index = index[np.linspace(0, index.size - 1, SHIFT_FIT_SAMPLES).astype(int)]
    form = columns(index)
    if a is not None:
        form = np.einsum("ij,njk->nik", a, form)
    x = np.hstack([calibration_rows(data, index), form.reshape(-1, columns.width)])
    scale = np.maximum(np.sqrt(np.mean(x**2, axis=0)), 1e-12)
    y = data.b_raw_nt[index].reshape(-1)
    coef, *_ = np.linalg.lstsq(x / scale, y, rcond=None)
    coef = coef / scale
    # calibration_rows: row i holds b / FIELD_SCALE_NT in columns 3 i .. 3 i + 2
    return float(coef[12]), np.asarray(coef[:9].reshape(3, 3) / FIELD_SCALE_NT)
