"""Telemetry to the diagnosis's arrays: reference field, rotations, Sun, RC index, crust.

:func:`diagnosis_data` turns a validated :class:`orbitcal.telemetry.Telemetry` into the plain
arrays of :class:`~orbitcal.diagnose.data.DiagnosisData`: the reference field in body axes
through :mod:`orbitcal.truth`, ITRS->body rotations through :mod:`orbitcal.frames`, Sun and
eclipse through :mod:`orbitcal.sun`, the RC index and a crustal model through
:mod:`orbitcal.field`.
"""

from __future__ import annotations

import warnings
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.options import DEFAULT_CRUST_MODEL, DiagnosisOptions
from orbitcal.diagnose.prior import CalibrationPrior
from orbitcal.diagnose.track import along_track
from orbitcal.errors import BadInputError, NotEnoughDataError

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.field._base import SphericalHarmonicModel
    from orbitcal.orbit import Propagator
    from orbitcal.telemetry import Telemetry

__all__ = [
    "CRUST_KNOT_SPACING_S",
    "CRUST_LOW_BAND_NMAX",
    "DEFAULT_CRUST_MODEL",
    "diagnosis_data",
    "field_body_nt",
    "field_itrs_nt",
    "rotation_itrs_to_body",
]


def rotation_itrs_to_body(
    t_utc_s: FloatArray, q_wxyz: FloatArray, *, attitude_frame: str = "GCRS"
) -> FloatArray:
    """Matrices ``R`` with ``v_body = R @ v_itrs``, shape (N, 3, 3).

    Parameters
    ----------
    t_utc_s : ndarray, shape (N,)
        POSIX seconds of UTC [s].
    q_wxyz : ndarray, shape (N, 4)
        Body orientation in the attitude frame (CONTRACT section 1 convention).
    attitude_frame : {"GCRS", "ITRS"}
    """
    from orbitcal import frames
    from orbitcal.attitude import quat_wxyz_to_matrix

    frame_to_body = quat_wxyz_to_matrix(q_wxyz)
    frame = attitude_frame.upper()
    if frame == "ITRS":
        return np.asarray(frame_to_body)
    if frame != "GCRS":
        raise BadInputError(
            f"attitude_frame must be GCRS or ITRS, not {attitude_frame!r}", field="attitude_frame"
        )
    gcrs_to_itrs = frames.gcrs_to_itrs_matrix(t_utc_s)
    return np.asarray(np.einsum("nij,nkj->nik", frame_to_body, gcrs_to_itrs))


#: Largest time between the samples at which the crustal model is evaluated [s]; between them
#: the field is interpolated along the track (cubic spline of the ITRS components in time, per
#: contiguous stretch). Its shortest wavelengths at orbit height are hundreds of km: on the
#: one-day 1 Hz Swarm A world (LCS-1 to degree 185, 86,400 samples) a 10 s spacing (76 km)
#: interpolates to 6.5e-5 nT rms and 2.5e-3 nT at worst, against a crustal field of 2.5 nT rms
#: and sensor noise of 0.1 nT and more (``benchmarks/results/diagnose_timing.md``), with a tenth
#: of the evaluations.
CRUST_KNOT_SPACING_S = 10.0


def field_itrs_nt(name: str, t: FloatArray, r_itrs_km: FloatArray) -> FloatArray:
    from orbitcal import frames
    from orbitcal.field import get_field

    radius, colat, lon = frames.itrs_to_spherical(r_itrs_km)
    b_nec = get_field(name).b_nec_nt(t, radius, colat, lon)
    return np.asarray(frames.nec_to_itrs(b_nec, r_itrs_km))


def field_body_nt(
    name: str,
    t: FloatArray,
    r_itrs_km: FloatArray,
    rot: FloatArray,
    *,
    knot_spacing_s: float | None = None,
) -> FloatArray | None:
    """The field model ``name`` in body axes at every sample [nT], shape (N, 3).

    With ``knot_spacing_s`` it is evaluated at most that far apart in time and interpolated
    along the track (:func:`orbitcal.diagnose.track.along_track`).
    """
    try:
        if knot_spacing_s is None:
            b_itrs = field_itrs_nt(name, t, r_itrs_km)
        else:
            b_itrs = along_track(partial(field_itrs_nt, name), t, r_itrs_km, knot_spacing_s)
    except ValueError as exc:  # FieldRangeError: outside the model's span
        warnings.warn(f"{name} not used as a candidate regressor: {exc}", stacklevel=3)
        return None
    return np.asarray(np.einsum("nij,nj->ni", rot, b_itrs))


def main_field_nmax(field_name: str) -> int:
    """The highest degree of the main-field terms of a reference field name (0 when none)."""
    from orbitcal.field import MAIN_FIELD_NAMES, get_field

    degrees = [
        int(getattr(get_field(term), "nmax", 0))
        for term in (x.strip() for x in field_name.split("+"))
        if term in MAIN_FIELD_NAMES
    ]
    return max(degrees, default=0)


#: The crustal candidate's degrees up to this one are also fitted on their own scale (the
#: ``bands`` form of :func:`orbitcal.diagnose.design.design_crustal`): there the lithospheric
#: spectrum meets the core's (they cross near degree 14), so a main field of degree 13 leaves
#: the core's small scales beside the crust's, and the models disagree on those degrees (CHAOS
#: counts them as core, to degree 20; its crust starts at 21). At 460 km LCS-1's degrees 14..20
#: are 1.5 nT rms of its 2.2 above degree 13.
CRUST_LOW_BAND_NMAX = 20


def _model_itrs_nt(
    model: SphericalHarmonicModel, t: FloatArray, r_itrs_km: FloatArray
) -> FloatArray:
    """A spherical-harmonic model's field at ITRS positions, ITRS components [nT]."""
    from orbitcal import frames

    radius, colat, lon = frames.itrs_to_spherical(r_itrs_km)
    return np.asarray(frames.nec_to_itrs(model.b_nec_nt(t, radius, colat, lon), r_itrs_km))


def crust_body_nt(
    crust_model: str, reference_field: str, t: FloatArray, r_itrs_km: FloatArray, rot: FloatArray
) -> FloatArray | None:
    """The crustal candidate in body axes [nT], (N, 3): the crustal model above the reference
    field's main-field degree (:func:`orbitcal.field.crust.crustal_field_above`), evaluated at
    most :data:`CRUST_KNOT_SPACING_S` apart along the track; None (with a warning) for a model
    that is not a crustal model of the catalogue or cannot be evaluated."""
    bands = crust_bands_body_nt(crust_model, reference_field, t, r_itrs_km, rot)
    return None if bands is None else bands[0]


def crust_bands_body_nt(
    crust_model: str, reference_field: str, t: FloatArray, r_itrs_km: FloatArray, rot: FloatArray
) -> tuple[FloatArray, FloatArray | None] | None:
    """:func:`crust_body_nt` and its part of degrees up to :data:`CRUST_LOW_BAND_NMAX` (None when
    the model has none there above the main field's degree, or is not a crustal model of the
    catalogue) [nT], (N, 3) each."""
    from orbitcal.field.crust import CRUSTAL_MODELS, crustal_field, crustal_field_above

    if crust_model not in CRUSTAL_MODELS:
        whole = field_body_nt(crust_model, t, r_itrs_km, rot, knot_spacing_s=CRUST_KNOT_SPACING_S)
        return None if whole is None else (whole, None)
    nmin = main_field_nmax(reference_field) + 1
    models = [crustal_field_above(crust_model, nmin)]
    if max(nmin, crustal_field(crust_model).nmin) <= CRUST_LOW_BAND_NMAX < models[0].nmax:
        models.append(crustal_field_above(crust_model, nmin, CRUST_LOW_BAND_NMAX))
    out: list[FloatArray] = []
    for model in models:
        try:
            b_itrs = along_track(partial(_model_itrs_nt, model), t, r_itrs_km, CRUST_KNOT_SPACING_S)
        except ValueError as exc:  # pragma: no cover - a static model has no span to leave
            warnings.warn(f"{crust_model} not used as a candidate regressor: {exc}", stacklevel=3)
            return None
        out.append(np.asarray(np.einsum("nij,nj->ni", rot, b_itrs)))
    return out[0], (out[1] if len(out) > 1 else None)


def diagnosis_data(
    telemetry: Telemetry,
    *,
    orbit: Propagator | None = None,
    options: DiagnosisOptions = DiagnosisOptions(),
    calibration_prior: CalibrationPrior | None = None,
) -> DiagnosisData:
    """Build the attribution's arrays from a telemetry table.

    Parameters
    ----------
    telemetry : Telemetry
        Validated table with quaternions (vector residuals need the attitude).
    orbit : Propagator, optional
        Orbit for positions when the table has none (an :class:`orbitcal.orbit.Orbit`).
    options : DiagnosisOptions
        Its ``field`` (reference field), ``attitude_frame``, ``crust_model`` (None skips the
        crustal model: ~1 s per 2000 samples at n = 185) and ``external_model`` (the RC-driven
        magnetospheric field for the external_field candidate) are used here.
    calibration_prior : CalibrationPrior, optional
        The calibration in service (:func:`orbitcal.diagnose.prior.prior_from_document`) as a
        prior on the 12 parameters: needed on short spans where a large external field is nearly
        parallel to the main field (a storm pass) and a free scale factor would absorb it.

    Raises
    ------
    BadInputError
        No attitude quaternions, or an unknown attitude frame.
    NotEnoughDataError
        Fewer than two samples.
    """
    from orbitcal.truth import truth_for_telemetry

    q_wxyz = _checked_quaternions(telemetry)
    attitude_frame = options.attitude_frame
    crust_model = options.crust_model
    truth = truth_for_telemetry(
        telemetry, orbit=orbit, attitude_frame=attitude_frame, field=options.field
    )
    from orbitcal.plausibility import check_table

    # a table in Tesla/Gauss/µT is named, not diagnosed (wrong elements are the orbit_error
    # effect's to find)
    check_table(
        telemetry.b_raw_nt, b_ref_mag_nt=np.linalg.norm(truth.b_itrs_nt, axis=1), orbit=False
    )
    t = np.asarray(telemetry.t_utc_s, dtype=float)
    rot = rotation_itrs_to_body(t, q_wxyz, attitude_frame=attitude_frame)
    r_itrs = np.asarray(truth.r_itrs_km, dtype=float)
    b_ref_body = np.einsum("nij,nj->ni", rot, truth.b_itrs_nt)
    illumination, sun_body = _sun_in_body(t, r_itrs, rot)
    x_hk, names = _housekeeping(telemetry)
    rc_index, b_ext_body = _ring_current(t, r_itrs, rot) if options.external_model else (None, None)
    bands = crust_bands_body_nt(crust_model, options.field, t, r_itrs, rot) if crust_model else None
    b_crust_body, b_crust_low_body = (None, None) if bands is None else bands
    return DiagnosisData(
        t_utc_s=t,
        b_raw_nt=np.asarray(telemetry.b_raw_nt, dtype=float),
        b_ref_body_nt=b_ref_body,
        rot_itrs_to_body=rot,
        r_itrs_km=r_itrs,
        x_hk=x_hk,
        hk_names=tuple(names),
        sunlit=illumination > 0.5,
        sun_body=sun_body,
        rc_index_nt=rc_index,
        b_crust_body_nt=b_crust_body,
        b_crust_low_body_nt=b_crust_low_body,
        crust_model=crust_model if b_crust_body is not None else None,
        reference_field=truth.field_name,
        illumination=illumination,
        b_ext_body_nt=b_ext_body,
        calibration_prior=calibration_prior,
        positions_measured=telemetry.r_itrs_km is not None,
        element_age_days=_element_age_days(orbit, t) if telemetry.r_itrs_km is None else None,
    )


def _element_age_days(orbit: Propagator | None, t_utc_s: FloatArray) -> float | None:
    """Days from an element set's epoch to the middle of the data (None without an epoch)."""
    epoch = getattr(orbit, "epoch_utc_s", None)
    if epoch is None or not np.isfinite(float(epoch)) or t_utc_s.size == 0:
        return None
    middle = 0.5 * (float(t_utc_s[0]) + float(t_utc_s[-1]))
    return (middle - float(epoch)) / 86400.0


def _checked_quaternions(telemetry: Telemetry) -> FloatArray:
    """The table's quaternions; the typed error a table without them or of one sample
    deserves."""
    if telemetry.q_wxyz is None:
        raise BadInputError(
            "the diagnosis needs attitude quaternions (q_w, q_x, q_y, q_z) to compare vectors",
            field="q_w",
        )
    if np.size(telemetry.t_utc_s) < 2:
        raise NotEnoughDataError(
            f"the diagnosis needs a time series and got {np.size(telemetry.t_utc_s)} sample(s); "
            "provide hours of telemetry (several orbits)"
        )
    return np.asarray(telemetry.q_wxyz)


def _sun_in_body(
    t: FloatArray, r_itrs_km: FloatArray, rot: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The visible fraction of the solar disc (conical shadow) [-] and the unit vector towards
    the Sun in the body frame [-], per sample."""
    from orbitcal import frames
    from orbitcal.sun import illumination_conical, sun_position_gcrs_km

    r_gcrs = frames.itrs_to_gcrs(r_itrs_km, t)
    sun_gcrs = sun_position_gcrs_km(t)
    illumination = np.asarray(illumination_conical(r_gcrs, sun_gcrs), dtype=float)
    s_gcrs = sun_gcrs - r_gcrs
    s_itrs = frames.gcrs_to_itrs(s_gcrs / np.linalg.norm(s_gcrs, axis=1, keepdims=True), t)
    return illumination, np.einsum("nij,nj->ni", rot, s_itrs)


def _housekeeping(telemetry: Telemetry) -> tuple[FloatArray, list[str]]:
    """The housekeeping regressors ``x_hk`` (N, k) and their names: the temperature, the
    magnetorquer dipoles and every finite numeric ``hk_*`` column."""
    names: list[str] = []
    cols: list[FloatArray] = []
    if telemetry.temperature_c is not None:
        names.append("temperature")
        cols.append(np.asarray(telemetry.temperature_c, dtype=float))
    if telemetry.mtq_am2 is not None:
        for k, axis in enumerate("xyz"):
            names.append(f"mtq_{axis}")
            cols.append(np.asarray(telemetry.mtq_am2[:, k], dtype=float))
    for key, values in sorted(telemetry.hk.items()):
        arr = np.asarray(values)
        if arr.dtype.kind in "fiu" and np.all(np.isfinite(arr)):
            names.append(key)
            cols.append(arr.astype(float))
    return (np.column_stack(cols) if cols else np.zeros((0, 0))), names


def _ring_current(
    t: FloatArray, r_itrs_km: FloatArray, rot: FloatArray
) -> tuple[FloatArray | None, FloatArray | None]:
    """The RC index at the samples [nT] and the RC-driven field in the body frame [nT]; both
    None, with a warning, when the index does not cover the samples."""
    try:
        from orbitcal.field.external import ring_current_field

        rc_e, rc_i = ring_current_field().rc_nt(t)
        rc_index = np.asarray(rc_e + rc_i, dtype=float)
        b_ext_body = field_body_nt("RC", t, r_itrs_km, rot)
    except ValueError as exc:
        # stacklevel 3: the warning names diagnosis_data's caller
        warnings.warn(f"RC index not used: {exc}", stacklevel=3)
        return None, None
    return rc_index, b_ext_body
