"""The diagnosis's arrays: :class:`DiagnosisData`, the samples and what is derived from them.

Plain data: the geometry derived from the samples (rates, gradients, magnetic coordinates) is
cached here; the fits' computations on them live with the fits
(:mod:`orbitcal.diagnose.calibration_columns` for the calibration's columns and basis).

Geometry helpers use the centred dipole of :mod:`orbitcal.geomag` (IGRF-14 at 2020.0), the same
one the simulator uses.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import BoolArray, FloatArray, IntArray
from orbitcal.diagnose.prior import CalibrationPrior
from orbitcal.diagnose.track import along_track
from orbitcal.geomag import dipole_axis_itrs, magnetic_latitude_deg

#: Roughly one LEO revolution [s]; a shorter span is "short" (re-exported by
#: :mod:`orbitcal.diagnose.span_options`; here so that the designs can use it without importing
#: the attribution that module's ``choose_options`` calls).
ORBIT_S = 5400.0

__all__ = ["FIELD_SCALE_NT", "ORBIT_S", "SECONDS_PER_DAY", "DiagnosisData", "contiguous_runs"]


#: Earth rotation rate about the ITRS z axis [rad/s] (IERS nominal).
EARTH_ROTATION_RAD_S = 7.292115e-5

#: Field scale used to keep design columns near unit size [nT].
FIELD_SCALE_NT = 5.0e4


SECONDS_PER_DAY = 86400.0


def contiguous_runs(t_s: FloatArray) -> list[slice]:
    """Contiguous runs of samples (a gap longer than 3 median steps starts a new run)."""
    if t_s.size < 2:
        return [slice(0, t_s.size)]
    dt = np.diff(t_s)
    step = float(np.median(dt))
    cuts = np.flatnonzero(dt > 3.0 * step) + 1
    edges = [0, *cuts.tolist(), t_s.size]
    return [slice(a, b) for a, b in itertools.pairwise(edges)]


#: Relative rotations of at most this angle take the closed-form log map (:func:`log_map`);
#: larger ones go through the quaternion, which stays accurate up to a half turn [rad].
LOG_MAP_CLOSED_FORM_MAX_RAD = 2.0


def log_map(rel: FloatArray) -> FloatArray:
    """Rotation vectors [rad] (N, 3) of rotation matrices (N, 3, 3): ``theta / (2 sin theta)``
    times the antisymmetric part's axial vector, with ``theta = atan2(|v| / 2, (tr - 1) / 2)``
    (its series ``1 + theta^2 / 6`` near zero); beyond :data:`LOG_MAP_CLOSED_FORM_MAX_RAD`,
    where ``sin theta`` loses the digits, through scipy's quaternion. Between neighbouring
    samples of a day at 1 Hz it is a tenth of the cost of ``Rotation.from_matrix(rel).as_rotvec()``
    and agrees with it to ~1e-16 rad."""
    v = np.stack(
        [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]],
        axis=1,
    )
    sin_theta = 0.5 * np.sqrt(np.sum(v * v, axis=1))
    cos_theta = 0.5 * (rel[:, 0, 0] + rel[:, 1, 1] + rel[:, 2, 2] - 1.0)
    theta = np.arctan2(sin_theta, cos_theta)
    small = sin_theta < 1e-6
    factor = np.where(small, 1.0 + theta**2 / 6.0, theta / np.where(small, 1.0, sin_theta))
    out = 0.5 * factor[:, None] * v
    large = theta > LOG_MAP_CLOSED_FORM_MAX_RAD
    if np.any(large):
        from scipy.spatial.transform import Rotation

        out[large] = Rotation.from_matrix(rel[large]).as_rotvec()
    return np.asarray(out)


def _time_derivative(t_s: FloatArray, y: FloatArray) -> FloatArray:
    """d y / d t per contiguous segment (second-order central differences) [unit of y / s]."""
    out = np.zeros_like(y)
    for seg in contiguous_runs(t_s):
        n = seg.stop - seg.start
        if n >= 3:
            out[seg] = np.gradient(y[seg], t_s[seg], axis=0, edge_order=2)
        elif n == 2:
            out[seg] = (y[seg][1] - y[seg][0]) / (t_s[seg][1] - t_s[seg][0])
    return out


#: Relative unevenness of the four steps around a sample below which the fourth-order stencil
#: of the body rate is used (:func:`_rate_fourth_order`) [-].
EVEN_STEPS_REL = 1e-3


def _rate_fourth_order(r: FloatArray, t_s: FloatArray) -> tuple[IntArray, FloatArray]:
    """The body rate [rad/s] at the samples of one contiguous run whose two neighbours on each
    side are evenly spaced (within :data:`EVEN_STEPS_REL`): ``(8 (th_1 - th_-1) - (th_2 - th_-2))
    / 12 h`` with ``th_k`` the log map of ``R(t + k h) R(t)^T``; exact for a steady spin, and
    fourth order in ``h`` where the rate changes. Returns the samples' positions and rates."""
    n = t_s.size
    i = np.arange(2, n - 2)
    steps = np.diff(t_s)
    h = steps[i]
    even = np.ones(i.size, dtype=bool)
    for d in (-2, -1, 1):
        even &= np.abs(steps[i + d] - h) <= EVEN_STEPS_REL * h
    i, h = i[even], h[even]

    def theta(k: int) -> FloatArray:
        rel = np.einsum("nij,nkj->nik", r[i + k], r[i])  # R(t + k h) R(t)^T, body axes
        return log_map(rel)

    rate = (8.0 * (theta(1) - theta(-1)) - (theta(2) - theta(-2))) / (12.0 * h)[:, None]
    return i, np.asarray(rate)


#: Largest time between the evaluations of the reference field's gradient along the track [s]
#: (:attr:`DiagnosisData.db_ref_body_drtn_nt_km`); interpolated between them. The core field's
#: gradient changes over thousands of km: at 10 s (76 km) the spline is exact to rounding.
GRADIENT_KNOT_SPACING_S = 10.0


@dataclass(frozen=True, eq=False)
class DiagnosisData:
    """Everything the attribution needs, as plain arrays (N samples, time-ordered).

    Attributes
    ----------
    t_utc_s : ndarray, shape (N,)
        Sample times, POSIX seconds of UTC [s].
    b_raw_nt : ndarray, shape (N, 3)
        Raw magnetometer output, sensor axes [nT].
    b_ref_body_nt : ndarray, shape (N, 3)
        Reference field (e.g. IGRF-14) at each sample, body frame [nT].
    rot_itrs_to_body : ndarray, shape (N, 3, 3)
        Rotation matrices with ``v_body = rot_itrs_to_body[n] @ v_itrs`` [-].
    r_itrs_km : ndarray, shape (N, 3)
        Positions, ITRS [km].
    x_hk : ndarray, shape (N, k)
        Housekeeping regressors (``temperature`` [degC], ``mtq_x..z`` [A m^2], ``hk_*``).
    hk_names : tuple of str
        Names of the ``x_hk`` columns.
    sunlit : ndarray of bool, shape (N,), optional
        True where the spacecraft is in sunlight.
    sun_body : ndarray, shape (N, 3), optional
        Unit vector towards the Sun, body frame [-].
    rc_index_nt : ndarray, shape (N,), optional
        Ring-current (RC) index interpolated at the sample times [nT].
    b_crust_body_nt : ndarray, shape (N, 3), optional
        A crustal field model at the samples, body frame [nT].
    b_crust_low_body_nt : ndarray, shape (N, 3), optional
        The part of ``b_crust_body_nt`` of its lowest degrees (to
        :data:`orbitcal.diagnose.prepare.CRUST_LOW_BAND_NMAX`), where the crust's spectrum meets
        the core's [nT].
    crust_model : str, optional
        Name of that crustal model (e.g. ``"LCS-1"``).
    reference_field : str
        Name of the reference field with its generation (e.g. ``"IGRF-14"``).
    illumination : ndarray, shape (N,), optional
        Visible fraction of the solar disc, 0 (umbra) to 1 [-]; refines ``sunlit``.
    b_ext_body_nt : ndarray, shape (N, 3), optional
        An RC-index-driven magnetospheric field model (``orbitcal.field`` ``"RC"``), body frame
        [nT].
    calibration_prior : CalibrationPrior, optional
        The calibration in service as a prior on the 12 parameters of every joint fit.
    positions_measured : bool
        True when positions come with the telemetry (GNSS, metre-level): orbit_error, which models
        the along-track error of a propagated element set, is then no candidate.
    element_age_days : float, optional
        Days from the epoch of the element set the positions were propagated from to the middle
        of the data (None for measured positions or an unknown epoch): an older set's orbit
        error may be larger.
    reference_fn : callable, optional
        ``reference_fn(t_utc_s, r_itrs_km) -> b_itrs_nt``: the reference field anywhere, for
        gradients off the track; default the ``orbitcal.truth`` model named ``reference_field``.
    """

    t_utc_s: FloatArray
    b_raw_nt: FloatArray
    b_ref_body_nt: FloatArray
    rot_itrs_to_body: FloatArray
    r_itrs_km: FloatArray
    x_hk: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    hk_names: tuple[str, ...] = ()
    sunlit: BoolArray | None = None
    sun_body: FloatArray | None = None
    rc_index_nt: FloatArray | None = None
    b_crust_body_nt: FloatArray | None = None
    b_crust_low_body_nt: FloatArray | None = None
    crust_model: str | None = None
    reference_field: str = "IGRF-14"
    illumination: FloatArray | None = None
    b_ext_body_nt: FloatArray | None = None
    calibration_prior: CalibrationPrior | None = None
    positions_measured: bool = False
    element_age_days: float | None = None
    reference_fn: Callable[[FloatArray, FloatArray], FloatArray] | None = None

    def __post_init__(self) -> None:
        n = self.t_utc_s.shape[0]
        if self.b_raw_nt.shape != (n, 3) or self.b_ref_body_nt.shape != (n, 3):
            raise ValueError("b_raw_nt and b_ref_body_nt must have shape (N, 3)")
        if self.rot_itrs_to_body.shape != (n, 3, 3) or self.r_itrs_km.shape != (n, 3):
            raise ValueError("rot_itrs_to_body must be (N, 3, 3) and r_itrs_km (N, 3)")
        if self.x_hk.size and self.x_hk.shape != (n, len(self.hk_names)):
            raise ValueError("x_hk must have shape (N, len(hk_names))")
        if np.any(np.diff(self.t_utc_s) <= 0):
            raise ValueError("t_utc_s must be strictly increasing")

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t_utc_s.shape[0])

    def subset(self, index: npt.NDArray[np.intp] | BoolArray | slice) -> DiagnosisData:
        """The same data restricted to some samples (order kept)."""

        def pick(a: FloatArray | BoolArray | None) -> FloatArray | BoolArray | None:
            return None if a is None else a[index]

        return DiagnosisData(
            t_utc_s=self.t_utc_s[index],
            b_raw_nt=self.b_raw_nt[index],
            b_ref_body_nt=self.b_ref_body_nt[index],
            rot_itrs_to_body=self.rot_itrs_to_body[index],
            r_itrs_km=self.r_itrs_km[index],
            x_hk=self.x_hk[index] if self.x_hk.size else self.x_hk,
            hk_names=self.hk_names,
            sunlit=pick(self.sunlit),  # type: ignore[arg-type]
            sun_body=pick(self.sun_body),  # type: ignore[arg-type]
            rc_index_nt=pick(self.rc_index_nt),  # type: ignore[arg-type]
            b_crust_body_nt=pick(self.b_crust_body_nt),  # type: ignore[arg-type]
            b_crust_low_body_nt=pick(self.b_crust_low_body_nt),  # type: ignore[arg-type]
            crust_model=self.crust_model,
            reference_field=self.reference_field,
            illumination=pick(self.illumination),  # type: ignore[arg-type]
            b_ext_body_nt=pick(self.b_ext_body_nt),  # type: ignore[arg-type]
            calibration_prior=self.calibration_prior,
            positions_measured=self.positions_measured,
            element_age_days=self.element_age_days,
            reference_fn=self.reference_fn,
        )

    def hk(self, name: str) -> FloatArray | None:
        """The housekeeping column ``name`` or None."""
        if name in self.hk_names and self.x_hk.size:
            return self.x_hk[:, self.hk_names.index(name)]
        return None

    # Derived geometry, computed once.
    @cached_property
    def b_ref_itrs_nt(self) -> FloatArray:
        """Reference field, ITRS [nT]."""
        return np.einsum("nji,nj->ni", self.rot_itrs_to_body, self.b_ref_body_nt)

    @cached_property
    def body_rate_itrs_rad_s(self) -> FloatArray:
        """Angular velocity of the body relative to ITRS, body axes [rad/s], shape (N, 3).

        From the rotation between the neighbouring samples (log map, central where possible), so a
        fast, steady spin is differentiated exactly rather than by chords; where the two samples
        on each side are evenly spaced, by the fourth-order central stencil of the log map
        relative to the sample (:func:`_rate_fourth_order`): a spin with a nutation of a few
        minutes' period changes its rate within the +-10 s of a central difference at a 10 s
        cadence, and the time-offset template built on the second-order rate was 2-3 % short
        (independent worlds' tumbling time offsets came out 2-3 % large, outside their 90 %
        intervals).
        """
        r = self.rot_itrs_to_body
        t = self.t_utc_s
        out = np.zeros((self.n, 3))
        for seg in contiguous_runs(t):
            idx = np.arange(seg.start, seg.stop)
            if idx.size < 2:
                continue
            lo = np.concatenate([idx[:1], idx[:-2], idx[-2:-1]])
            hi = np.concatenate([idx[1:2], idx[2:], idx[-1:]])
            rel = np.einsum("nij,nkj->nik", r[hi], r[lo])  # R(hi) R(lo)^T, body axes
            rotvec = log_map(rel)
            out[idx] = rotvec / (t[hi] - t[lo])[:, None]
            if idx.size >= 5:
                inner, rate = _rate_fourth_order(r[idx], t[idx])
                out[idx[inner]] = rate
        return out

    @cached_property
    def db_ref_body_dt_nt_s(self) -> FloatArray:
        """Time derivative of the reference field seen in the body frame [nT/s].

        ``d(R b_itrs)/dt = w x (R b_itrs) + R d(b_itrs)/dt`` with the body rate ``w`` from the
        attitude (exact for a steady spin) and the Earth-fixed field differenced along the track.
        """
        db_itrs = _time_derivative(self.t_utc_s, self.b_ref_itrs_nt)
        return np.asarray(
            np.cross(self.body_rate_itrs_rad_s, self.b_ref_body_nt)
            + np.einsum("nij,nj->ni", self.rot_itrs_to_body, db_itrs)
        )

    @cached_property
    def db_ref_body_drtn_nt_km(self) -> FloatArray:
        """Gradients of the reference field along radial, along-track, cross-track [nT/km].

        Shape (N, 3, 3): ``[:, :, k]`` is the body-frame field change per km of displacement along
        the k-th of (radial, inertial along-track, orbit normal). An element set that is late or
        early puts the spacecraft elsewhere in its orbit at the same time: the displacement is
        along the inertial velocity, while the Earth stays where it is. A time-tag error instead
        moves the sample along the velocity relative to the Earth; the two differ by the Earth's
        rotation (0.46 km/s x cos(latitude) of 7.6 km/s, mostly across track), and after the 12
        parameters absorb the attitude term of a steady spin, that difference is all that tells
        the two effects apart. Central differences of the reference field (``reference_fn``, else
        the model named ``reference_field``) over +-5 km, rotated into the body frame.
        """
        return self.gradients_at(self.r_itrs_km, self.orbit_frame_itrs)

    @property
    def reference_field_fn(self) -> Callable[[FloatArray, FloatArray], FloatArray]:
        """``fn(t_utc_s, r_itrs_km) -> b_itrs_nt``: :attr:`reference_fn`, else the model named
        :attr:`reference_field`."""
        if self.reference_fn is not None:
            return self.reference_fn
        from orbitcal.truth import reference_field_itrs_nt

        name = self.reference_field

        def field_fn(t: FloatArray, r: FloatArray) -> FloatArray:
            return np.asarray(reference_field_itrs_nt(t, r, field=name))

        return field_fn

    @property
    def orbit_frame_itrs(self) -> FloatArray:
        """Unit vectors radial, inertial along-track and orbit normal at each sample, ITRS
        components, (N, 3, 3) with ``[:, :, k]`` the k-th (the along-track one along the
        velocity in inertial space, the Earth's rotation added to the ITRS velocity). Computed
        when asked (the gradients once, a large orbit error's form): not held, 72 B a sample."""
        r = self.r_itrs_km
        omega = np.array([0.0, 0.0, EARTH_ROTATION_RAD_S])
        v_in = _time_derivative(self.t_utc_s, r) + np.cross(omega, r)
        radial = r / np.linalg.norm(r, axis=1, keepdims=True)
        normal = np.cross(radial, v_in)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        along = np.cross(normal, radial)
        return np.stack([radial, along, normal], axis=2)

    def gradients_at(self, r_itrs_km: FloatArray, frame_itrs: FloatArray) -> FloatArray:
        """The reference field's gradients at positions ``r_itrs_km`` (N, 3) along the three
        directions of ``frame_itrs`` (N, 3, 3), in the body frame of each sample [nT/km],
        (N, 3, 3): central differences over +-5 km, evaluated every
        :data:`GRADIENT_KNOT_SPACING_S` along the track and interpolated."""
        field_fn = self.reference_field_fn
        h_km = 5.0

        def gradient_itrs(t: FloatArray, r_and_dirs: FloatArray) -> FloatArray:
            pos, dirs = r_and_dirs[:, :3], r_and_dirs[:, 3:].reshape(-1, 3, 3)
            out = np.empty((t.shape[0], 3, 3))
            for k in range(3):
                plus = np.asarray(field_fn(t, pos + h_km * dirs[:, :, k]))
                minus = np.asarray(field_fn(t, pos - h_km * dirs[:, :, k]))
                out[:, :, k] = (plus - minus) / (2.0 * h_km)
            return out

        grad = along_track(
            gradient_itrs,
            self.t_utc_s,
            np.column_stack([r_itrs_km, frame_itrs.reshape(-1, 9)]),
            GRADIENT_KNOT_SPACING_S,
        )
        out = np.empty((self.n, 3, 3))
        for k in range(3):
            out[:, :, k] = np.einsum("nij,nj->ni", self.rot_itrs_to_body, grad[:, :, k])
        return out

    @cached_property
    def dipole_axis_body(self) -> FloatArray:
        """The dipole axis (SM z) in the body frame, per sample [-]."""
        return np.einsum("nij,j->ni", self.rot_itrs_to_body, dipole_axis_itrs())

    @cached_property
    def mlat_deg(self) -> FloatArray:
        """Centred-dipole magnetic latitude [deg]."""
        return magnetic_latitude_deg(self.r_itrs_km)

    @cached_property
    def b_hat_body(self) -> FloatArray:
        """Unit vector along the reference field, body frame [-]."""
        b = self.b_ref_body_nt
        return b / np.linalg.norm(b, axis=1, keepdims=True)

    @cached_property
    def transverse_body(self) -> FloatArray:
        """Two unit vectors perpendicular to B, body frame, shape (N, 2, 3).

        The first is magnetic east (dipole axis x position, projected perpendicular to B), the
        second completes the right-handed set with B.
        """
        r_hat = self.r_itrs_km / np.linalg.norm(self.r_itrs_km, axis=1, keepdims=True)
        east_itrs = np.cross(dipole_axis_itrs(), r_hat)
        east_body = np.einsum("nij,nj->ni", self.rot_itrs_to_body, east_itrs)
        b = self.b_hat_body
        e1 = east_body - np.sum(east_body * b, axis=1, keepdims=True) * b
        e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-12)
        e2 = np.cross(b, e1)
        return np.stack([e1, e2], axis=1)

    @cached_property
    def sm_equatorial_body(self) -> FloatArray | None:
        """The SM x and y axes (the dipole equator's sunward and duskward directions) in the
        body frame, shape (N, 2, 3) [-] (None without the Sun's direction)."""
        if self.sun_body is None:
            return None
        z = self.dipole_axis_body
        x = self.sun_body - np.sum(self.sun_body * z, axis=1, keepdims=True) * z
        x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12)
        return np.stack([x, np.cross(z, x)], axis=1)

    @cached_property
    def mlt_angle_rad(self) -> FloatArray | None:
        """Magnetic local time angle [rad]: 0 at magnetic noon, +pi/2 at dusk (None without Sun).

        The Sun direction is projected on the dipole equator (SM x); SM y = dipole axis x SM x.
        """
        if self.sun_body is None:
            return None
        z = dipole_axis_itrs()
        sun_itrs = np.einsum("nji,nj->ni", self.rot_itrs_to_body, self.sun_body)
        x_sm = sun_itrs - np.outer(sun_itrs @ z, z)
        x_sm /= np.maximum(np.linalg.norm(x_sm, axis=1, keepdims=True), 1e-12)
        y_sm = np.cross(z, x_sm)
        r = self.r_itrs_km
        return np.arctan2(np.sum(r * y_sm, axis=1), np.sum(r * x_sm, axis=1))

    @cached_property
    def orbit_phase_rad(self) -> FloatArray:
        """Orbit phase, like the argument of latitude, from the ITRS track [rad].

        The phase is unwrapped along the track and measured from the northward crossing of the
        equator, which is all the attitude-error harmonics need.
        """
        lat = np.arcsin(self.r_itrs_km[:, 2] / np.linalg.norm(self.r_itrs_km, axis=1))
        vz = _time_derivative(self.t_utc_s, self.r_itrs_km)[:, 2]
        # lat = asin(sin i sin u): recover u in [0, 2 pi) from lat and the sign of the z velocity.
        s = np.clip(np.sin(lat) / max(np.max(np.abs(np.sin(lat))), 1e-9), -1.0, 1.0)
        u = np.arcsin(s)
        return np.where(vz >= 0.0, np.mod(u, 2 * np.pi), np.pi - u)
