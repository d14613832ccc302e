"""The effects catalogue: one candidate model per CONTRACT section-5 name, with its witness.

Every candidate is a *linear* extension of the 12-parameter calibration. The forward model of the
raw measurement, per sensor axis ``i`` and sample ``n``, is

    b_raw[n, i] = sum_j A[i, j] b_ref[n, j] + o[i] + sum_k c[k] G[n, i, k] + noise

where ``b_ref`` is the reference field in the body frame [nT], ``A`` (3x3) and ``o`` (3) are the 12
calibration parameters and ``G`` (N, 3, p) is the effect's design block (its *regressors*) with the
``p`` effect parameters ``c``. Effects that physically add a field outside the sensor (external,
crustal, field-aligned currents, Sun-driven) and effects inside it (temperature, magnetorquer,
nonlinearity, drift) are both written this way: with ``A`` close to identity the distinction changes
the parameters by the (small) calibration error only.

Each effect declares its *witness*: the data it needs (a temperature channel, magnetorquer commands,
the Sun direction, a crustal model ...). An effect whose witness is missing is not a candidate.

Geometry helpers use the centred dipole of :mod:`orbitcal.geomag` (IGRF-14 at 2020.0), the same
one the simulator uses.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property, partial

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.columns import (
    Columns,
    Factor,
    FunctionColumns,
    Index,
    PerAxisColumns,
    ScaledVectorColumns,
    chunk_slices,
    take,
    triangular_factor,
)
from orbitcal.diagnose.prior import CalibrationPrior
from orbitcal.diagnose.track import along_track
from orbitcal.geomag import dipole_axis_itrs, magnetic_latitude_deg

__all__ = [
    "CATALOGUE",
    "EFFECT_NAMES",
    "DesignBlock",
    "DiagnosisData",
    "Effect",
    "get_effect",
]


#: Earth rotation rate about the ITRS z axis [rad/s] (IERS nominal).
EARTH_ROTATION_RAD_S = 7.292115e-5

#: Field scale used to keep design columns near unit size [nT].
FIELD_SCALE_NT = 5.0e4

#: Every effect name of CONTRACT section 5 except ``none``, in catalogue order.
EFFECT_NAMES: tuple[str, ...] = (
    "temperature",
    "magnetorquer",
    "time_offset",
    "external_field",
    "crustal_field",
    "sun_driven",
    "nonlinearity",
    "orbit_error",
    "parameter_drift",
    "field_aligned_currents",
    "attitude_error",
)

SECONDS_PER_DAY = 86400.0


def _segments(t_s: FloatArray) -> list[slice]:
    """Contiguous runs of samples (a gap longer than 3 median steps starts a new run)."""
    if t_s.size < 2:
        return [slice(0, t_s.size)]
    dt = np.diff(t_s)
    step = float(np.median(dt))
    cuts = np.flatnonzero(dt > 3.0 * step) + 1
    edges = [0, *cuts.tolist(), t_s.size]
    return [slice(a, b) for a, b in itertools.pairwise(edges)]


def _time_derivative(t_s: FloatArray, y: FloatArray) -> FloatArray:
    """d y / d t per contiguous segment (second-order central differences) [unit of y / s]."""
    out = np.zeros_like(y)
    for seg in _segments(t_s):
        n = seg.stop - seg.start
        if n >= 3:
            out[seg] = np.gradient(y[seg], t_s[seg], axis=0, edge_order=2)
        elif n == 2:
            out[seg] = (y[seg][1] - y[seg][0]) / (t_s[seg][1] - t_s[seg][0])
    return out


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
    crust_model: str | None = None
    reference_field: str = "IGRF-14"
    illumination: FloatArray | None = None
    b_ext_body_nt: FloatArray | None = None
    calibration_prior: CalibrationPrior | None = None
    positions_measured: bool = False
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

    def calibration_rows(self, index: Index) -> FloatArray:
        """The 12 calibration columns (``b_ref / FIELD_SCALE_NT`` per axis and an offset) of the
        samples ``index``, rows sample-major, shape (3 m, 12)."""
        b = self.b_ref_body_nt[index] / FIELD_SCALE_NT
        x = np.zeros((b.shape[0], 3, 12))
        for i in range(3):
            x[:, i, 3 * i : 3 * i + 3] = b
            x[:, i, 9 + i] = 1.0
        return x.reshape(-1, 12)

    def calibration_r_inv_of(self, index: npt.NDArray[np.intp]) -> FloatArray:
        """Inverse ``R^-1`` (12, 12) of the triangular factor of the 12 calibration columns on
        the samples ``index``, ``X = Q R``: an orthonormal basis of the calibration there is
        ``X R^-1``, built a block of samples at a time (the whole 3N x 12 ``Q``, 288 B per
        sample, is never held)."""
        blocks = (self.calibration_rows(index[part]) for part in chunk_slices(index.size))
        return np.asarray(np.linalg.inv(triangular_factor(blocks, 12)), dtype=np.float64)

    @cached_property
    def calibration_r_inv(self) -> FloatArray:
        """:meth:`calibration_r_inv_of` all samples, computed once per data set."""
        return self.calibration_r_inv_of(np.arange(self.n))

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
            crust_model=self.crust_model,
            reference_field=self.reference_field,
            illumination=pick(self.illumination),  # type: ignore[arg-type]
            b_ext_body_nt=pick(self.b_ext_body_nt),  # type: ignore[arg-type]
            calibration_prior=self.calibration_prior,
            positions_measured=self.positions_measured,
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
        fast, steady spin is differentiated exactly rather than by chords.
        """
        from scipy.spatial.transform import Rotation

        r = self.rot_itrs_to_body
        t = self.t_utc_s
        out = np.zeros((self.n, 3))
        for seg in _segments(t):
            idx = np.arange(seg.start, seg.stop)
            if idx.size < 2:
                continue
            lo = np.concatenate([idx[:1], idx[:-2], idx[-2:-1]])
            hi = np.concatenate([idx[1:2], idx[2:], idx[-1:]])
            rel = np.einsum("nij,nkj->nik", r[hi], r[lo])  # R(hi) R(lo)^T, body axes
            rotvec = Rotation.from_matrix(rel).as_rotvec()
            out[idx] = rotvec / (t[hi] - t[lo])[:, None]
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
        field_fn = self.reference_fn
        if field_fn is None:
            from orbitcal.truth import reference_field_itrs_nt

            name = self.reference_field

            def field_fn(t: FloatArray, r: FloatArray) -> FloatArray:
                return np.asarray(reference_field_itrs_nt(t, r, field=name))

        r = self.r_itrs_km
        omega = np.array([0.0, 0.0, EARTH_ROTATION_RAD_S])
        v_in = _time_derivative(self.t_utc_s, r) + np.cross(omega, r)
        radial = r / np.linalg.norm(r, axis=1, keepdims=True)
        normal = np.cross(radial, v_in)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        along = np.cross(normal, radial)
        h_km = 5.0

        def gradient_itrs(t: FloatArray, r_and_dirs: FloatArray) -> FloatArray:
            pos, dirs = r_and_dirs[:, :3], r_and_dirs[:, 3:].reshape(-1, 3, 3)
            out = np.empty((t.shape[0], 3, 3))
            for k in range(3):
                plus = np.asarray(field_fn(t, pos + h_km * dirs[:, k]))
                minus = np.asarray(field_fn(t, pos - h_km * dirs[:, k]))
                out[:, :, k] = (plus - minus) / (2.0 * h_km)
            return out

        # Evaluated every GRADIENT_KNOT_SPACING_S along the track and interpolated.
        grad = along_track(
            gradient_itrs,
            self.t_utc_s,
            np.column_stack([r, radial, along, normal]),
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


@dataclass(frozen=True)
class DesignBlock:
    """An effect's regressors and parameter names.

    Attributes
    ----------
    source : ndarray, shape (N, 3, p), or Columns
        The regressors, or (:mod:`orbitcal.diagnose.columns`) their factors, from which the rows
        of the samples asked for are built: most blocks are products of quantities held anyway,
        and held whole every candidate's every variant would grow with N.
    names : list of str
        Parameter names with their units, e.g. ``"dt_s"``.
    variant : str
        Which form of the model was used (e.g. ``"trend"`` or ``"step"`` for drift).
    alternatives : sequence of DesignBlock
        Other forms of the same effect; the attribution keeps the one that fits the *training*
        blocks best (never the held-out ones).
    refine : callable, optional
        Forms near this one (a bias step a little earlier or later), tried when this one is
        chosen among the alternatives; each may refine further.
    """

    source: FloatArray | Columns
    names: list[str]
    variant: str = ""
    alternatives: Sequence[DesignBlock] = ()
    refine: Callable[[], Sequence[DesignBlock]] | None = field(default=None, compare=False)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.source.n if callable(self.source) else self.source.shape[0])

    @property
    def width(self) -> int:
        """Number of parameters ``p``."""
        return len(self.names)

    def rows(self, index: Index) -> FloatArray:
        """Regressors of the samples ``index``, shape (m, 3, p); parameter ``k`` adds
        ``c[k] * rows[:, :, k]`` [nT] in the sensor/body frame."""
        if callable(self.source):
            return self.source(index)
        return self.source[index]

    def axis_columns(self) -> list[npt.NDArray[np.intp]]:
        """Per sensor axis, the parameters whose regressors are not all zero on that axis's rows
        (all of them unless the block acts on one axis per column)."""
        if isinstance(self.source, PerAxisColumns):
            return self.source.axis_columns()
        return [np.arange(self.width)] * 3

    def axis_rows(self, index: Index) -> list[FloatArray]:
        """Per sensor axis ``i``, the regressors of :meth:`axis_columns` on axis ``i``'s rows of
        the samples ``index``, (m, len(axis_columns()[i])) each."""
        if isinstance(self.source, PerAxisColumns):
            return self.source.axis_rows(index)
        g = self.rows(index)
        return [g[:, i, :] for i in range(3)]

    @property
    def g(self) -> FloatArray:
        """All regressors, shape (N, 3, p) (built whole: for small data and checks)."""
        return self.rows(slice(None))

    def apply(self, coef: FloatArray) -> FloatArray:
        """The field ``G @ coef`` at every sample [nT], shape (N, 3), a block at a time."""
        if not callable(self.source):
            return np.asarray(self.source @ coef)
        out = np.empty((self.n, 3))
        for part in chunk_slices(self.n):
            out[part] = self.rows(part) @ coef
        return out

    def all_finite(self) -> bool:
        """True when every regressor is finite (checked a block of samples at a time)."""
        if not callable(self.source):
            return bool(np.all(np.isfinite(self.source)))
        return all(bool(np.all(np.isfinite(self.rows(p)))) for p in chunk_slices(self.n))


DesignFn = Callable[[DiagnosisData, BoolArray], DesignBlock | None]


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect.

    Attributes
    ----------
    name : str
        CONTRACT section-5 effect name.
    physics : str
        One line: what the model is.
    witness : str
        One line: what in the data reveals it (and which inputs it needs).
    design : callable
        ``design(data, train_mask) -> DesignBlock | None``; None when the witness is missing.
        ``train_mask`` marks the samples a data-driven choice (e.g. a step time) may look at.
    absorbed_by_calibration : bool
        True when the 12 parameters can absorb it in some attitude regimes (needs split fits).
    design_beside : callable, optional
        ``design_beside(data, train, fixed)``: the design found beside already selected effects
        (their regressors fitted jointly with it), for designs found by a scan of the data.
    """

    name: str
    physics: str
    witness: str
    design: DesignFn
    absorbed_by_calibration: bool = False
    design_beside: (
        Callable[[DiagnosisData, BoolArray, Sequence[DesignBlock]], DesignBlock | None] | None
    ) = None


def _tau_days(data: DiagnosisData, train: BoolArray) -> FloatArray:
    t0 = float(np.mean(data.t_utc_s[train]))
    return np.asarray((data.t_utc_s - t0) / SECONDS_PER_DAY)


def _varies(x: FloatArray | None, *, tol: float = 1e-9) -> bool:
    return x is not None and bool(np.all(np.isfinite(x))) and float(np.std(x)) > tol


def _design_temperature(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    temp = data.hk("temperature")
    if temp is None or not _varies(temp):
        return None
    dtemp = temp - float(np.mean(temp[train]))
    g = PerAxisColumns(data.n, [dtemp, partial(_scaled_by, data.b_ref_body_nt, dtemp)])
    names = [f"offset_{a}_nt_per_degc" for a in "xyz"] + [
        f"scale_{a}_per_degc_x{FIELD_SCALE_NT:.0e}" for a in "xyz"
    ]
    return DesignBlock(g, names)


def _design_magnetorquer(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    cols = [data.hk(f"mtq_{a}") for a in "xyz"]
    if all(c is None or not _varies(c) for c in cols):
        return None
    kinds = [c if c is not None else np.zeros(data.n) for c in cols]
    g = PerAxisColumns(data.n, kinds, axis_major=True)
    names = []
    for i in range(3):
        for j in range(3):
            names.append(f"coupling_{'xyz'[i]}{'xyz'[j]}_nt_per_am2")
    return DesignBlock(g, names)


def _design_time_offset(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    first = data.db_ref_body_dt_nt_s
    # Second order of the shift, b(t + dt) - b(t) = dt b' + dt^2 b''/2: under a fast spin the
    # cross term of the body rate and the along-track change of the field (not absorbed by the
    # 12 parameters) reaches ~1 nT for dt = 1 s at 1 deg/s; its coefficient is free (~dt^2).
    second = 0.5 * _time_derivative(data.t_utc_s, first)
    return DesignBlock(
        first[:, :, None],
        ["dt_s"],
        alternatives=(
            DesignBlock(
                ScaledVectorColumns(data.n, [first, second], [None, None]),
                ["dt_s", "dt_squared_s2"],
                "second_order",
            ),
        ),
    )


#: Decay times of the ring current's recovery phase tried by the external-field model [h].
EXTERNAL_RECOVERY_TIMES_H: tuple[float, ...] = tuple(
    float(x) for x in np.geomspace(2.0, 24.0, 10).round(2)
)


def _design_external(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    axis = data.dipole_axis_body
    tau = _tau_days(data, train)
    options = [
        DesignBlock(
            ScaledVectorColumns(data.n, [axis, axis], [None, tau]),
            ["uniform_along_dipole_nt", "uniform_trend_nt_per_day"],
            variant="dipole_axis",
        )
    ]
    # A storm's recovery phase: the ring-current field decays as exp(-t / tau) with tau of a few
    # to twenty hours (Burton et al. 1975: 7.7 h; O'Brien & McPherron 2000: 3-20 h), which a
    # linear trend extrapolates badly over the held-out blocks; tau from a grid, by training BIC.
    t_rel_s = data.t_utc_s - float(data.t_utc_s[0])
    for tau_h in EXTERNAL_RECOVERY_TIMES_H:
        decay = partial(_recovery_decay, t_rel_s, tau_h)
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, axis], [None, decay]),
                ["uniform_along_dipole_nt", "uniform_recovering_nt"],
                variant=f"recovery_{tau_h:.3g}h",
            )
        )
    rc = data.rc_index_nt
    if rc is not None and _varies(rc[train], tol=1.0):
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, axis], [None, rc - float(np.mean(rc[train]))]),
                ["uniform_along_dipole_nt", "rc_coefficient"],
                variant="rc_index",
            )
        )
    if data.b_ext_body_nt is not None and _varies(data.b_ext_body_nt[train, 0], tol=1e-3):
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, data.b_ext_body_nt], [None, None]),
                ["uniform_along_dipole_nt", "rc_model_scale"],
                variant="rc_model",
            )
        )
        # The RC index is hourly: a storm's ring current also changes within the hour.
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, data.b_ext_body_nt, axis], [None, None, tau]),
                ["uniform_along_dipole_nt", "rc_model_scale", "uniform_trend_nt_per_day"],
                variant="rc_model+trend",
            )
        )
    first = options[0]
    return DesignBlock(first.source, first.names, first.variant, tuple(options[1:]))


def _recovery_decay(t_rel_s: FloatArray, tau_h: float, index: Index) -> FloatArray:
    """The recovery-phase decay ``exp(-t / tau)`` of the samples ``index`` [-]."""
    return np.asarray(np.exp(-t_rel_s[index] / (tau_h * 3600.0)))


def _scaled_by(b_nt: FloatArray, x: Factor, index: Index) -> FloatArray:
    """``x * b / FIELD_SCALE_NT`` of the samples ``index``, (m, 3)."""
    return np.asarray(take(x, index)[:, None] * (b_nt[index] / FIELD_SCALE_NT))


def _field_power(b_nt: FloatArray, power: int, index: Index) -> FloatArray:
    """``(b / FIELD_SCALE_NT) ** power`` of the samples ``index``, (m, 3)."""
    return np.asarray((b_nt[index] / FIELD_SCALE_NT) ** power)


def _design_crustal(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    if data.b_crust_body_nt is None:
        return None
    return DesignBlock(
        data.b_crust_body_nt[:, :, None], ["crust_scale"], variant=data.crust_model or "model"
    )


def _design_sun(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    if data.sun_body is None or (data.sunlit is None and data.illumination is None):
        return None
    lit = (
        np.asarray(data.illumination, dtype=float)
        if data.illumination is not None
        else np.asarray(data.sunlit, dtype=float)
    )
    cols = [lit * data.sun_body[:, k] for k in range(3)]
    names = []
    for k in "xyz":
        names += [f"sun_{k}_to_{a}_nt" for a in "xyz"]
    if 0.02 < float(np.mean(lit[train] > 0.5)) < 0.98:
        # With eclipses in the data the sunlit offset is separable from the calibration offset.
        cols = [lit, *cols]
        names = [f"sunlit_offset_{a}_nt" for a in "xyz"] + names
    return DesignBlock(PerAxisColumns(data.n, cols), names)


def _design_nonlinearity(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    b = data.b_ref_body_nt
    g = PerAxisColumns(data.n, [partial(_field_power, b, 2), partial(_field_power, b, 3)])
    names = [f"quadratic_{a}_nt" for a in "xyz"] + [f"cubic_{a}_nt" for a in "xyz"]
    return DesignBlock(g, names)


def _design_orbit(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    if data.positions_measured:
        return None  # GNSS positions: no element-set error to model
    grads = data.db_ref_body_drtn_nt_km
    grad = grads[:, :, 1]
    tau = _tau_days(data, train)
    growing = DesignBlock(
        ScaledVectorColumns(data.n, [grad, grad], [None, tau]),
        ["along_track_km", "along_track_rate_km_per_day"],
        variant="growing",
    )
    # An element set's error in all three directions (Hill / Clohessy-Wiltshire motion): the
    # along-track error grows; an eccentricity error adds once-per-rev radial and (twice as large)
    # along-track terms, an inclination or node error once-per-rev cross-track terms.
    u = data.orbit_phase_rad
    c, sn = np.cos(u), np.sin(u)
    rad, nrm = grads[:, :, 0], grads[:, :, 2]
    rtn = DesignBlock(
        ScaledVectorColumns(
            data.n,
            [grad, grad, grad, grad, rad, rad, rad, nrm, nrm],
            [None, tau, c, sn, None, c, sn, c, sn],
        ),
        [
            "along_track_km",
            "along_track_rate_km_per_day",
            "along_track_cos_km",
            "along_track_sin_km",
            "radial_km",
            "radial_cos_km",
            "radial_sin_km",
            "cross_track_cos_km",
            "cross_track_sin_km",
        ],
        variant="rtn",
    )
    return DesignBlock(
        grad[:, :, None], ["along_track_km"], "constant", alternatives=(growing, rtn)
    )


def _design_drift(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    tau = _tau_days(data, train)
    b = data.b_ref_body_nt
    names_b = [f"bias_{a}" for a in "xyz"]
    names_s = [f"scale_{a}_x{FIELD_SCALE_NT:.0e}" for a in "xyz"]
    trend = PerAxisColumns(data.n, [tau, partial(_scaled_by, b, tau)])
    best = DesignBlock(trend, [n + "_nt_per_day" for n in names_b + names_s], variant="trend")
    # A step at one of ~20 candidate times inside the training span, chosen on training only by the
    # residual of the joint fit (done by the caller through ``choose_variant``).
    t_train = data.t_utc_s[train]
    span = float(t_train[-1] - t_train[0]) if t_train.size > 1 else 0.0
    if span <= 0.0:
        return best
    names = [n + "_step_nt" for n in names_b + names_s] + [n + "_nt_per_day" for n in names_b]

    fracs = np.linspace(0.1, 0.9, DRIFT_STEP_TIMES)
    spacing_s = float(fracs[1] - fracs[0]) * span
    cadence_s = float(np.median(np.diff(data.t_utc_s)))
    finest_s = max(DRIFT_STEP_RESOLUTION_S, cadence_s)
    steps = [
        _drift_step(data, names, tau, float(t_train[0] + f * span), spacing_s / 2.0, finest_s)
        for f in fracs
    ]
    return DesignBlock(best.source, best.names, best.variant, alternatives=tuple(steps))


#: Step times tried on the training span (10 % to 90 %), then refined by halving.
DRIFT_STEP_TIMES = 17
#: The refinement of a step time stops at this spacing [s] (or at the cadence, if coarser).
DRIFT_STEP_RESOLUTION_S = 30.0


def _drift_step(
    data: DiagnosisData,
    names: list[str],
    tau: FloatArray,
    ts: float,
    half_s: float,
    finest_s: float,
) -> DesignBlock:
    """The drift's bias and scale step at ``ts`` with its bias trend. Its refinement tries the
    step ``half_s`` earlier and later (each refining by half again) while ``half_s`` is at least
    ``finest_s``: a step misplaced by half the grid spacing leaves a box of the step's height
    that long, ~4 nT RMS over four orbits for a 30 nT step, which other effects then take up."""
    b = data.b_ref_body_nt
    step = partial(_step_at, data.t_utc_s, ts)
    kinds: list[Factor] = [step, partial(_scaled_by, b, step), tau]
    refine = None
    if half_s >= finest_s:
        refine = partial(_drift_steps_near, data, names, tau, ts, half_s, finest_s)
    return DesignBlock(
        PerAxisColumns(data.n, kinds), names, variant=f"step@{ts:.0f}+trend", refine=refine
    )


def _drift_steps_near(
    data: DiagnosisData,
    names: list[str],
    tau: FloatArray,
    ts: float,
    half_s: float,
    finest_s: float,
) -> list[DesignBlock]:
    """The step ``half_s`` earlier and later, and at ``ts`` again refining by half as much."""
    return [
        _drift_step(data, names, tau, ts + d, half_s / 2.0, finest_s)
        for d in (-half_s, half_s, 0.0)
    ]


def _step_at(t_s: FloatArray, ts: float, index: Index) -> FloatArray:
    """1 from the time ``ts`` on, 0 before, at the samples ``index``."""
    return np.asarray((t_s[index] >= ts).astype(float))


#: Magnetic-latitude centres [deg] and width [deg] of the field-aligned-current basis bumps.
FAC_CENTRES_DEG: tuple[float, ...] = tuple(float(c) for c in np.arange(58.0, 82.0, 2.0))
FAC_WIDTH_DEG = 1.5
FAC_MIN_MLAT_DEG = 58.0


def _design_fac(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    mlat = data.mlat_deg
    if not np.any(np.abs(mlat[train]) > FAC_MIN_MLAT_DEG):
        return None
    # Region-1/2 currents reverse between dawn and dusk: each latitude bump is modulated by sin
    # and cos of the magnetic local time angle (when the Sun direction is known); two passes at
    # different local times are fitted exactly, and a constant term would be collinear with them.
    mods = ("",) if data.mlt_angle_rad is None else ("_sin_mlt", "_cos_mlt")
    bumps: list[tuple[float, float, str]] = []
    names = []
    for hemi, sign in (("n", 1.0), ("s", -1.0)):
        for c in FAC_CENTRES_DEG:
            bump = _fac_bump(mlat, sign, c)
            if float(np.max(bump[train], initial=0.0)) < 0.05:
                continue
            for suffix in mods:
                bumps.append((sign, c, suffix))
                names.append(f"east_{hemi}{c:.0f}{suffix}_nt")
    if not bumps:
        return None
    fn = partial(_fac_columns, data, tuple(bumps))
    return DesignBlock(FunctionColumns(data.n, len(bumps), fn), names)


def _fac_bumps(mlat_deg: FloatArray, sign: float, centres_deg: Sequence[float]) -> FloatArray:
    """Latitude bumps of the field-aligned-current basis of one hemisphere, (N, len(centres)):
    zero equatorward of their range, all centres in one exponential."""
    x = sign * mlat_deg
    on = np.flatnonzero(x >= FAC_MIN_MLAT_DEG - 3 * FAC_WIDTH_DEG)
    out = np.zeros((x.shape[0], len(centres_deg)))
    if on.size and len(centres_deg):
        d = (x[on, None] - np.asarray(centres_deg, dtype=float)) / FAC_WIDTH_DEG
        out[on] = np.exp(-0.5 * d**2)
    return out


def _fac_bump(mlat_deg: FloatArray, sign: float, centre_deg: float) -> FloatArray:
    """One latitude bump of the field-aligned-current basis (:func:`_fac_bumps`)."""
    return _fac_bumps(mlat_deg, sign, [centre_deg])[:, 0]


def _fac_columns(
    data: DiagnosisData, bumps: tuple[tuple[float, float, str], ...], index: Index
) -> FloatArray:
    """The field-aligned-current regressors of the samples ``index``, (m, 3, len(bumps)): built
    when a fit asks for them (two dozen columns held for the whole attribution took 95 MB at
    86,400 samples)."""
    east = data.transverse_body[index, 0, :]
    phi = data.mlt_angle_rad
    mlat = data.mlat_deg[index]
    mods = {} if phi is None else {"_sin_mlt": np.sin(phi[index]), "_cos_mlt": np.cos(phi[index])}
    weights = np.zeros((mlat.shape[0], len(bumps)))
    for sign in (1.0, -1.0):
        centres = sorted({c for sg, c, _ in bumps if sg == sign})
        values = _fac_bumps(mlat, sign, centres)
        for k, (sg, c, suffix) in enumerate(bumps):
            if sg == sign:
                w = values[:, centres.index(c)]
                weights[:, k] = w * mods[suffix] if suffix in mods else w
    return np.asarray(east[:, :, None] * weights[:, None, :])


#: Periods scanned for the attitude-error sinusoids [s] (log-spaced), and how many are kept.
ATTITUDE_PERIODS_S = np.geomspace(1200.0, 30000.0, 160)
ATTITUDE_MAX_TERMS = 3
#: At most this many passes of the cyclic period refinement (it stops at the first pass that
#: changes no period).
ATTITUDE_REFINE_PASSES = 8
#: Sets of periods carried from one greedy step of the scan to the next (beam search).
ATTITUDE_BEAM = 3

#: The rows of the scan's orthonormal basis are kept between its uses up to this size [B].
SCAN_Q_CACHE_BYTES = 16 * 2**20

#: Samples per block of the batched period scan (memory ~ periods x block x 8 B per array).
SCAN_BLOCK_SAMPLES = 4096

#: At most this many training samples enter the period scan (every k-th): the shortest period
#: scanned (1,200 s) then still has ~100 samples per cycle on a day at 1 Hz, and the scan costs
#: the same beyond. The regressors of the periods found use every sample.
SCAN_MAX_SAMPLES = 5_000


def _rotation_columns(data: DiagnosisData, index: Index | None = None) -> FloatArray:
    """e_k x B (k = x, y, z): field change of a small rotation about body axis k, (N, 3, 3)
    (of the samples ``index`` only, if given)."""
    b = data.b_ref_body_nt if index is None else data.b_ref_body_nt[index]
    return np.stack([np.cross(np.eye(3)[k], b) for k in range(3)], axis=2)


def _design_attitude(
    data: DiagnosisData, train: BoolArray, *, fixed: Sequence[DesignBlock] = ()
) -> DesignBlock | None:
    # A slowly varying small rotation dtheta(t) of the attitude: db = dtheta x B. The constant part
    # is a misalignment the 12 parameters absorb; the variation is a few sinusoids (thermal
    # distortion, star-tracker errors) whose periods are found by a matching-pursuit scan of the
    # training residual (periods shorter than 80 % of the training span). Beside effects already
    # selected (``fixed``), their regressors are projected out with the calibration's: each
    # period's gain is then what it adds to a joint fit of them all.
    t = data.t_utc_s - float(data.t_utc_s[train][0])
    span = float(t[train][-1]) if np.any(train) else 0.0
    periods = ATTITUDE_PERIODS_S[0.8 * span > ATTITUDE_PERIODS_S]
    if periods.size == 0:
        return None
    scan = _AttitudeScan(data, train, fixed)
    # The scan needs, per period, only 6 x 6 and 6 x q sums over the samples: the gain of the
    # projected columns P[R c, R s] (P = I - QQ^T, R = rotation columns, c, s = cos, sin) is
    # g^T (G + eps tr(G) I)^-1 g with G = A - B^T B, A = [[sum c^2 M, sum cs M], [., sum s^2 M]],
    # M = R^T R, B = [sum c K, sum s K], K = Q^T R per sample, g = [sum c R^T r, sum s R^T r].
    # All periods of a grid are summed at once, a block of samples at a time. Q (the calibration
    # columns and the sinusoids of the periods kept) is never held whole: it is X R^-1, the
    # columns X built per block and R from a block-updated QR (:class:`_AttitudeScan`).

    def first_best(periods_s: FloatArray, g: FloatArray, floor: float) -> tuple[float, float]:
        # the first period whose gain is the largest, if it beats ``floor`` (a sequential scan
        # keeping strictly better gains picks the same one)
        if g.size == 0:
            return floor, 0.0
        i = int(np.argmax(g))
        if not g[i] > floor:
            return floor, 0.0
        return float(g[i]), float(periods_s[i])

    def peaks(periods_s: FloatArray, g: FloatArray, n: int) -> list[float]:
        # the ``n`` largest local maxima of the gain over the grid, at least 5 % apart
        order = np.argsort(-g, kind="stable")
        out: list[float] = []
        for i in order:
            if len(out) == n or not g[i] > 0.0:
                break
            p = float(periods_s[i])
            left = g[i - 1] if i > 0 else -np.inf
            right = g[i + 1] if i + 1 < g.size else -np.inf
            if g[i] >= left and g[i] >= right and all(abs(p / q - 1.0) >= 0.05 for q in out):
                out.append(p)
        return out

    def refine(chosen: list[float], passes: int) -> tuple[list[float], float]:
        # Cyclic refinement: re-fit each period with the others fixed (close periods that one
        # training span cannot resolve at once are separated this way), until a pass changes
        # none; returns the periods and their training residual sum of squares.
        chosen = list(chosen)
        for _ in range(passes):
            before = list(chosen)
            for j in range(len(chosen)):
                basis = scan.basis(chosen[:j] + chosen[j + 1 :])
                r_now = scan.residual(basis)
                grid = chosen[j] * np.linspace(0.94, 1.06, 61)
                _, p_best = first_best(grid, scan.gains(grid, r_now, basis), -1.0)
                chosen[j] = p_best if p_best else chosen[j]
            if chosen == before:
                break
        r_end = scan.residual(scan.basis(chosen))
        return chosen, float(r_end @ r_end)

    # Beam search over the greedy steps: the best ``ATTITUDE_BEAM`` sets of periods are carried
    # from step to step (each extended by the best peaks of its gain curve), so that a first
    # period that a greedy scan would take from a mixture of several sinusoids cannot lock the
    # others out; the set with the smallest training residual after refinement wins.
    beams: list[tuple[float, list[float]]] = [(0.0, [])]
    for _ in range(ATTITUDE_MAX_TERMS):
        grown: list[tuple[float, list[float]]] = []
        for _score, chosen in beams:
            basis = scan.basis(chosen)
            r_now = scan.residual(basis)
            rss_now = float(r_now @ r_now)
            free = np.array(
                [not any(abs(float(p) / c - 1.0) < 0.05 for c in chosen) for p in periods], bool
            )
            for start in peaks(
                periods[free], scan.gains(periods[free], r_now, basis), ATTITUDE_BEAM
            ):
                # Refine the period on a fine grid (+-2.5 %): phase errors grow over the
                # held-out span.
                fine = start * np.linspace(0.975, 1.025, 51)
                g_fine = scan.gains(fine, r_now, basis)
                i = int(np.argmax(g_fine))
                period, gain = float(fine[i]), float(g_fine[i])
                key = sorted([*chosen, period])
                if any(
                    all(abs(a / b - 1.0) < 0.01 for a, b in zip(key, sorted(c), strict=True))
                    for _, c in grown
                ):
                    continue
                grown.append((rss_now - gain, [*chosen, period]))
        if not grown:
            break
        grown.sort(key=lambda t: t[0])
        beams = grown[:ATTITUDE_BEAM]
    if not beams[0][1]:
        return None
    # one refinement pass for every set, then the best set refined to convergence
    first = [refine(chosen, 1) for _, chosen in beams]
    chosen = refine(min(first, key=lambda t: t[1])[0], ATTITUDE_REFINE_PASSES - 1)[0]
    names = [
        f"dtheta_{axis}_{fname}_{period:.0f}s_mrad"
        for period in chosen
        for fname in ("cos", "sin")
        for axis in "xyz"
    ]
    fn = partial(_attitude_columns, data, float(data.t_utc_s[train][0]), tuple(chosen))
    return DesignBlock(
        FunctionColumns(data.n, len(names), fn),
        names,
        variant="periods_s=" + ",".join(f"{p:.0f}" for p in chosen),
    )


#: Samples per run of the factored sinusoids in :func:`_cos_sin`.
_TRIG_RUN = 64


def _cos_sin(w_rad_s: FloatArray, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``cos(w t)`` and ``sin(w t)``, (periods, samples).

    On evenly spaced samples ``t = t_j + k dt`` (runs of :data:`_TRIG_RUN`) the exponential
    factors as ``exp(i w t_j) exp(i w k dt)``: one complex exponential per run and per offset
    instead of two per sample, three times faster and equal to ~4e-15 (a product of two
    rounded unit phasors); uneven times are evaluated directly.
    """
    m = t_s.shape[0]
    runs = m // _TRIG_RUN
    if runs >= 2 and m == runs * _TRIG_RUN:
        dt = float(t_s[1] - t_s[0])
        offsets = dt * np.arange(_TRIG_RUN)
        starts = t_s[::_TRIG_RUN]
        if dt > 0.0 and np.array_equal(t_s, (starts[:, None] + offsets[None, :]).reshape(-1)):
            z = (
                np.exp(1j * np.outer(w_rad_s, starts))[:, :, None]
                * np.exp(1j * np.outer(w_rad_s, offsets))[:, None, :]
            ).reshape(w_rad_s.shape[0], m)
            return np.ascontiguousarray(z.real), np.ascontiguousarray(z.imag)
    phase = np.outer(w_rad_s, t_s)
    return np.cos(phase), np.sin(phase)


class _AttitudeScan:
    """The training samples of the attitude period scan, read a block at a time.

    A *basis* is the periods kept with ``M`` for the columns ``X`` = (12 calibration columns, the
    regressors of ``fixed``, then cos and sin of each period times the rotation columns):
    ``Q = X M`` is orthonormal and spans what the scan projects out (``M = R^-1`` of ``X = Q R``,
    or its pseudo-inverse when fixed regressors repeat the calibration's); its rows are built per
    block of samples.
    """

    def __init__(
        self, data: DiagnosisData, train: BoolArray, fixed: Sequence[DesignBlock] = ()
    ) -> None:
        self.data = data
        self.fixed = list(fixed)
        idx = np.flatnonzero(train)
        self.idx = idx[:: max(1, -(-idx.size // SCAN_MAX_SAMPLES))]
        self.t = data.t_utc_s[self.idx] - float(data.t_utc_s[self.idx[0]])
        self.y = data.b_raw_nt[self.idx].reshape(-1)
        self.n = int(self.idx.size)
        # Per block, what no period changes: the rotation columns, their products R^T R and the
        # columns of the calibration and of ``fixed`` (at most SCAN_MAX_SAMPLES samples:
        # ~0.4 MB each for the first two, 0.1 MB per column for the last).
        self._q_of: FloatArray | None = None
        self._q: dict[int, FloatArray] = {}
        self._rot = [_rotation_columns(data, self.idx[a0:a1]) * 1e-3 for a0, a1 in self.blocks()]
        self._rtr = [np.matmul(np.swapaxes(r, 1, 2), r).reshape(-1, 9) for r in self._rot]
        self._base = [
            np.concatenate(
                [data.calibration_rows(self.idx[a0:a1])]
                + [bl.rows(self.idx[a0:a1]).reshape(-1, bl.width) for bl in self.fixed],
                axis=1,
            )
            for a0, a1 in self.blocks()
        ]

    def blocks(self) -> list[tuple[int, int]]:
        return [
            (a, min(a + SCAN_BLOCK_SAMPLES, self.n)) for a in range(0, self.n, SCAN_BLOCK_SAMPLES)
        ]

    def rot(self, a0: int, a1: int) -> FloatArray:
        """Rotation columns per mrad of the block, (m, 3, 3)."""
        return self._rot[a0 // SCAN_BLOCK_SAMPLES]

    def columns(self, periods: Sequence[float], a0: int, a1: int) -> FloatArray:
        """The columns X of the block, (3 m, 12 + fixed + 6 len(periods))."""
        parts = [self._base[a0 // SCAN_BLOCK_SAMPLES]]
        if periods:
            rt, tt = self.rot(a0, a1), self.t[a0:a1]
            for period in periods:
                w = 2 * np.pi / period
                cols = np.concatenate(
                    [rt * np.cos(w * tt)[:, None, None], rt * np.sin(w * tt)[:, None, None]],
                    axis=2,
                )
                parts.append(cols.reshape(-1, 6))
        return np.concatenate(parts, axis=1)

    def basis(self, periods: Sequence[float]) -> tuple[tuple[float, ...], FloatArray]:
        """The periods and ``R^-1`` of their columns (block-updated QR)."""
        width = 12 + sum(bl.width for bl in self.fixed) + 6 * len(periods)
        r = triangular_factor((self.columns(periods, a0, a1) for a0, a1 in self.blocks()), width)
        if not self.fixed:
            return tuple(periods), np.asarray(np.linalg.inv(r))
        # X = Q R = Q U S V': X V S^-1 = Q U, orthonormal on the directions S does not cut.
        _, s, vt = np.linalg.svd(r)
        keep = s > 1e-10 * s[0]
        return tuple(periods), np.asarray(vt[keep].T / s[keep])

    def q_rows(self, basis: tuple[tuple[float, ...], FloatArray], a0: int, a1: int) -> FloatArray:
        """Rows of ``Q`` of the block; those of the latest basis are kept when they are small
        (its residual and gains read them three times)."""
        if self._q_of is not basis[1]:
            self._q_of, self._q = basis[1], {}
        q = self._q.get(a0)
        if q is None:
            q = np.asarray(self.columns(basis[0], a0, a1) @ basis[1])
            if 3 * self.n * basis[1].shape[1] * 8 <= SCAN_Q_CACHE_BYTES:
                self._q[a0] = q
        return q

    def residual(self, basis: tuple[tuple[float, ...], FloatArray]) -> FloatArray:
        """``y - Q Q^T y`` over the training rows, (3 n,)."""
        qty = np.zeros(basis[1].shape[1])
        for a0, a1 in self.blocks():
            qty += self.q_rows(basis, a0, a1).T @ self.y[3 * a0 : 3 * a1]
        out = np.empty_like(self.y)
        for a0, a1 in self.blocks():
            rows = slice(3 * a0, 3 * a1)
            out[rows] = self.y[rows] - self.q_rows(basis, a0, a1) @ qty
        return out

    def gains(
        self,
        periods_s: FloatArray,
        r_now: FloatArray,
        basis: tuple[tuple[float, ...], FloatArray],
    ) -> FloatArray:
        """Gain in fit of the 6 columns of each period, projected off the basis."""
        n_q = basis[1].shape[1]
        w = 2 * np.pi / np.asarray(periods_s, dtype=np.float64)
        p_n = w.size
        acc_m = np.zeros((3, p_n, 9))
        acc_k = np.zeros((2, p_n, 3 * n_q))
        acc_v = np.zeros((2, p_n, 3))
        for a0, a1 in self.blocks():
            m = a1 - a0
            rt = self.rot(a0, a1)
            q3 = self.q_rows(basis, a0, a1).reshape(m, 3, n_q)
            m_blk = self._rtr[a0 // SCAN_BLOCK_SAMPLES]
            k_blk = q3[:, 0, :, None] * rt[:, 0, None, :]  # K = Q^T R per sample
            for i in (1, 2):
                k_blk += q3[:, i, :, None] * rt[:, i, None, :]
            k_blk = k_blk.reshape(m, -1)
            v_blk = np.matmul(r_now[3 * a0 : 3 * a1].reshape(m, 1, 3), rt)[:, 0, :]
            c, s_ = _cos_sin(w, self.t[a0:a1])
            acc_m[0] += (c * c) @ m_blk
            acc_m[1] += (c * s_) @ m_blk
            acc_m[2] += (s_ * s_) @ m_blk
            acc_k[0] += c @ k_blk
            acc_k[1] += s_ @ k_blk
            acc_v[0] += c @ v_blk
            acc_v[1] += s_ @ v_blk
        m3 = acc_m.reshape(3, p_n, 3, 3)
        gram = np.empty((p_n, 6, 6))
        gram[:, :3, :3] = m3[0]
        gram[:, :3, 3:] = m3[1]
        gram[:, 3:, :3] = np.swapaxes(m3[1], 1, 2)
        gram[:, 3:, 3:] = m3[2]
        # B = Q^T [R c, R s]: (p, q, 6), columns in the order (cos x,y,z, sin x,y,z)
        bq = np.concatenate([acc_k[0].reshape(p_n, n_q, 3), acc_k[1].reshape(p_n, n_q, 3)], axis=2)
        gram -= np.einsum("pqa,pqb->pab", bq, bq)
        rhs = np.concatenate([acc_v[0], acc_v[1]], axis=1)
        tr = np.trace(gram, axis1=1, axis2=2)
        reg = gram + 1e-9 * tr[:, None, None] * np.eye(6)
        out = np.zeros(p_n)
        try:
            sol = np.linalg.solve(reg, rhs[:, :, None])[:, :, 0]
            out = np.einsum("pa,pa->p", rhs, sol)
        except np.linalg.LinAlgError:
            for i in range(p_n):
                with contextlib.suppress(np.linalg.LinAlgError):
                    out[i] = float(rhs[i] @ np.linalg.solve(reg[i], rhs[i]))
        return np.asarray(out)


def _attitude_columns(
    data: DiagnosisData, t0_s: float, periods_s: tuple[float, ...], index: Index
) -> FloatArray:
    """The attitude-error regressors of the periods kept at the samples ``index``, (m, 3,
    6 x periods): built when a fit asks for them instead of held for the whole attribution."""
    t = data.t_utc_s[index] - t0_s
    rot = _rotation_columns(data, index) * 1e-3  # per mrad
    g = np.empty((t.shape[0], 3, 6 * len(periods_s)))
    col = 0
    for period in periods_s:
        w = 2 * np.pi / period
        for f in (np.cos(w * t), np.sin(w * t)):
            for k in range(3):
                np.multiply(rot[:, :, k], f[:, None], out=g[:, :, col])
                col += 1
    return g


CATALOGUE: tuple[Effect, ...] = (
    Effect(
        "temperature",
        "offset and scale factor linear in the sensor temperature",
        "a temperature channel; residual correlates with it (often with sunlight)",
        _design_temperature,
        absorbed_by_calibration=True,
    ),
    Effect(
        "magnetorquer",
        "3x3 coupling of the magnetorquer dipole commands into the sensor",
        "mtq_x, mtq_y, mtq_z commands; residual steps when they switch",
        _design_magnetorquer,
    ),
    Effect(
        "time_offset",
        "a constant time-tag error dt: db = dt * d(B_body)/dt",
        "residual follows the body-frame time derivative of B (attitude motion included)",
        _design_time_offset,
        absorbed_by_calibration=True,
    ),
    Effect(
        "external_field",
        "uniform magnetospheric field along the dipole (SM z) axis: ring current, "
        "constant plus RC-index-driven (or a per-window trend when no index covers the data)",
        "residual along the dipole axis, same sign at all latitudes; follows the RC/Dst index",
        _design_external,
    ),
    Effect(
        "crustal_field",
        "static lithospheric field fixed to the Earth (a crustal model, scaled)",
        "residual repeats with position on the ground track; needs a crustal model",
        _design_crustal,
    ),
    Effect(
        "sun_driven",
        "field organised by the Sun direction in the body frame, sunlit only (Swarm's dB_Sun)",
        "sunlit vs eclipse split fits disagree; needs the Sun direction and eclipse flag",
        _design_sun,
        absorbed_by_calibration=True,
    ),
    Effect(
        "nonlinearity",
        "quadratic and cubic terms of the sensor transfer function, per axis",
        "residual grows with |B| on an axis faster than linearly",
        _design_nonlinearity,
    ),
    Effect(
        "orbit_error",
        "along-track position error (constant plus growth with time): "
        "db = ds * dB/ds along the inertial velocity (the Earth fixed at the sample time)",
        "residual follows the along-track gradient of the field, not the attitude motion; "
        "needs positions propagated from a TLE/OMM (not measured ones)",
        _design_orbit,
        absorbed_by_calibration=True,
    ),
    Effect(
        "parameter_drift",
        "trend or step in the biases and scale factors",
        "split fits of consecutive time blocks disagree; the held-out error grows with time",
        _design_drift,
        absorbed_by_calibration=True,
    ),
    Effect(
        "field_aligned_currents",
        "transverse field at high magnetic latitude: bumps in |magnetic latitude| > 58 deg along "
        "magnetic east made perpendicular to B, modulated by magnetic local time (dawn/dusk)",
        "residual concentrated at |magnetic latitude| > 60 deg, perpendicular to B",
        _design_fac,
    ),
    Effect(
        "attitude_error",
        "a slowly varying attitude error dtheta(t): db = dtheta x B, dtheta a sum of up to three "
        "sinusoids with periods found on the training blocks",
        "vector residual perpendicular to B while the scalar residual stays clean",
        _design_attitude,
        absorbed_by_calibration=True,
        design_beside=lambda data, train, fixed: _design_attitude(data, train, fixed=fixed),
    ),
)

assert tuple(e.name for e in CATALOGUE) == EFFECT_NAMES


def get_effect(name: str) -> Effect:
    """The catalogue entry called ``name``; raises KeyError for unknown names."""
    for effect in CATALOGUE:
        if effect.name == name:
            return effect
    raise KeyError(f"unknown effect {name!r}; known: {', '.join(EFFECT_NAMES)}")
