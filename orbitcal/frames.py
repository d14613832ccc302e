"""Reference frames: GCRS ↔ ITRS (IAU 2006/2000A), TEME ↔ ITRS, spherical, geodetic and NEC.

Conventions
-----------
* Vectors are arrays of shape ``(N, 3)`` (a single ``(3,)`` broadcasts); times are ``t_utc_s``,
  POSIX seconds of UTC, shape ``(N,)`` (see :mod:`orbitcal.timescales`).
* ``M = gcrs_to_itrs_matrix(t)`` gives ``r_itrs = M @ r_gcrs``. It is Skyfield's
  ``framelib.itrs.rotation_at(t)`` (IAU 2006 precession, IAU 2000A nutation, UT1 − UTC and polar
  motion from the EOP table in use, :func:`orbitcal.timescales.skyfield_timescale`: an installed
  IERS finals2000A gives both, the shipped fallback — Skyfield's builtin table — UT1 − UTC only,
  so W = I there), computed fast: written in the CIO form of IERS Conventions 2010 eq. 5.1,
  ``M = W · R3(ERA) · C``, where ``C = R3(ERA − GAST) · N · P · B`` is GCRS → CIRS. The slow parts
  ``C`` and ``W`` (and ΔT = TT − UT1) come from Skyfield on a coarse grid (``step_s``, 1 h by
  default) and are interpolated linearly; the Earth rotation angle (IAU 2000 Resolution B1.8) is
  evaluated exactly at every sample. Agreement with Skyfield per sample: < 1 mas (see tests).
* TEME (the SGP4 frame): ``r_itrs = W · R3(θ_GMST82(UT1)) · r_teme`` and
  ``v_itrs = W · (R3(θ) v_teme − ω × R3(θ) r_teme)``, Vallado et al. 2006 (AIAA 2006-6753,
  Appendix C), as Skyfield's ``sgp4lib.TEME`` frame and ``TEME_to_ITRF``.
* Spherical: geocentric radius [km], colatitude θ [deg] from +z, longitude φ [deg] east of
  Greenwich, in ITRS.
* Geodetic: WGS84 (NIMA TR8350.2: a = 6378.137 km, 1/f = 298.257223563), latitude and longitude
  [deg], height above the ellipsoid [km].
* NEC: geocentric North (−θ̂), East (+φ̂), Centre (−r̂, down) at a position, the frame of Swarm's
  ``B_NEC`` and of the field models.
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.errors import OutOfRangeError
from orbitcal.timescales import skyfield_timescale, tables_epoch, tai_minus_utc_s

__all__ = [
    "OMEGA_EARTH_RAD_S",
    "WGS84_A_KM",
    "WGS84_INV_F",
    "earth_rotation_angle_rad",
    "gcrs_to_itrs",
    "gcrs_to_itrs_matrix",
    "gcrs_to_teme",
    "gcrs_to_teme_matrix",
    "geodetic_to_itrs",
    "gmst82_rad",
    "itrs_to_gcrs",
    "itrs_to_geodetic",
    "itrs_to_nec",
    "itrs_to_spherical",
    "itrs_to_teme",
    "nec_basis_itrs",
    "nec_to_itrs",
    "spherical_to_itrs",
    "teme_to_gcrs",
    "teme_to_itrs",
    "teme_to_itrs_matrix",
]


#: WGS84 semi-major axis [km] (NIMA TR8350.2, 3rd ed., table 3.1).
WGS84_A_KM = 6378.137
#: WGS84 inverse flattening (NIMA TR8350.2, table 3.1).
WGS84_INV_F = 298.257223563
_WGS84_F = 1.0 / WGS84_INV_F
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)
_WGS84_B_KM = WGS84_A_KM * (1.0 - _WGS84_F)

#: Nominal Earth rotation rate [rad/s] (IERS Conventions 2010, table 1.1; NIMA TR8350.2).
OMEGA_EARTH_RAD_S = 7.292115e-5

_DAY_S = 86_400.0
_TT_MINUS_TAI_S = 32.184  # IAU 1991 Resolution A4 / IERS Conventions 2010 eq. 10.6
_J2000_POSIX_S = 946_728_000.0  # 2000-01-01T12:00:00 (JD 2451545.0) as a POSIX-style count
_DEFAULT_STEP_S = 3_600.0
_GRID_LOCK = threading.Lock()


# --- small helpers ------------------------------------------------------------------------------


def _vec(v: npt.ArrayLike, name: str = "vector") -> FloatArray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape (..., 3), got {arr.shape}")
    return arr


def _times(t_utc_s: npt.ArrayLike) -> FloatArray:
    t = np.atleast_1d(np.asarray(t_utc_s, dtype=np.float64))
    if t.ndim != 1:
        raise ValueError(f"t_utc_s must have shape (N,), got {t.shape}")
    return t


def _mv(m: FloatArray, v: FloatArray) -> FloatArray:
    """``m @ v`` row by row: m (N,3,3) or (3,3), v (N,3) or (3,)."""
    return np.einsum("...ij,...j->...i", m, v)


def _mtv(m: FloatArray, v: FloatArray) -> FloatArray:
    """``m.T @ v`` row by row."""
    return np.einsum("...ji,...j->...i", m, v)


def _r3_rows(angle_rad: FloatArray, m: FloatArray) -> FloatArray:
    """``R3(angle) @ m`` for m (N,3,3), R3 the frame rotation [[c, s, 0], [−s, c, 0], [0, 0, 1]]."""
    c = np.cos(angle_rad)[:, None]
    s = np.sin(angle_rad)[:, None]
    out = np.empty_like(m)
    out[:, 0] = c * m[:, 0] + s * m[:, 1]
    out[:, 1] = -s * m[:, 0] + c * m[:, 1]
    out[:, 2] = m[:, 2]
    return out


# --- time arguments -----------------------------------------------------------------------------


def _tt_s(t_utc_s: FloatArray) -> FloatArray:
    """TT as a POSIX-style count [s]."""
    return t_utc_s + tai_minus_utc_s(t_utc_s) + _TT_MINUS_TAI_S


def earth_rotation_angle_rad(t_ut1_s: npt.ArrayLike) -> FloatArray:
    """Earth rotation angle ERA(UT1) [rad], in [0, 2π) (IAU 2000 Res. B1.8; IERS 2010 eq. 5.15).

    Parameters
    ----------
    t_ut1_s : array_like, shape (N,)
        UT1 as a POSIX-style count [s] (``t_utc_s + (UT1 − UTC)``).
    """
    t = np.asarray(t_ut1_s, dtype=np.float64)
    days = np.floor(t / _DAY_S)
    day_frac = (t - days * _DAY_S) / _DAY_S
    du = (days - (_J2000_POSIX_S - 43_200.0) / _DAY_S - 0.5) + day_frac  # JD(UT1) − 2451545.0
    turns = 0.7790572732640 + 0.00273781191135448 * du + (day_frac + 0.5)
    return np.mod(turns, 1.0) * (2.0 * math.pi)


def gmst82_rad(t_ut1_s: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Greenwich mean sidereal time of 1982 (IAU 1982; Vallado et al. 2006 appendix C) [rad].

    Returns ``(theta_rad, theta_dot_rad_s)`` as Skyfield's ``sgp4lib.theta_GMST1982``.
    """
    t = np.asarray(t_ut1_s, dtype=np.float64)
    days = np.floor(t / _DAY_S)
    day_frac = (t - days * _DAY_S) / _DAY_S
    du = (days - (_J2000_POSIX_S - 43_200.0) / _DAY_S - 0.5) + day_frac
    tc = du / 36_525.0
    g = 67_310.54841 + (8_640_184.812866 + (0.093104 + (-6.2e-6) * tc) * tc) * tc
    dg = 8_640_184.812866 + (0.093104 * 2.0 + (-6.2e-6 * 3.0) * tc) * tc
    theta = np.mod(day_frac + 0.5 + np.mod(g / _DAY_S, 1.0), 1.0) * (2.0 * math.pi)
    theta_dot = (1.0 + dg / (_DAY_S * 36_525.0)) * (2.0 * math.pi) / _DAY_S
    return theta, theta_dot


# --- slow parts on a grid -----------------------------------------------------------------------


def _grid_nodes(
    k: npt.NDArray[np.int64], step_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Skyfield's C (GCRS→CIRS), W (polar motion) and ΔT at TT grid nodes ``k * step_s``."""
    from skyfield.earthlib import earth_rotation_angle

    ts = skyfield_timescale()
    tt_s = k.astype(np.float64) * step_s
    days = np.floor(tt_s / _DAY_S)
    frac = (tt_s - days * _DAY_S) / _DAY_S
    t = ts.tt_jd(2_440_587.5 + days, frac)
    # C = R3(ERA − GAST) · M  (Skyfield's Time.C, with the ERA from the split UT1 date).
    eq_origins = earth_rotation_angle(t.whole, t.ut1_fraction) - t.gast / 24.0
    m = np.moveaxis(np.asarray(t.M), -1, 0)
    c = _r3_rows(-2.0 * math.pi * np.atleast_1d(np.asarray(eq_origins)), m)
    if ts.polar_motion_table is not None:
        w = np.moveaxis(np.asarray(t.polar_motion_matrix()), -1, 0)
    else:
        w = np.broadcast_to(np.eye(3), (k.size, 3, 3)).copy()
    delta_t_s = np.atleast_1d(np.asarray(t.delta_t, dtype=np.float64))
    return c, w, delta_t_s


_GRID_CACHE: OrderedDict[tuple[float, int, bytes], tuple[FloatArray, FloatArray, FloatArray]] = (
    OrderedDict()
)
_GRID_CACHE_SIZE = 8


def _grid_cached(
    k: npt.NDArray[np.int64], step_s: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`_grid_nodes` with a small LRU cache keyed by the node set (repeat calls are free)."""
    # The timescale is rebuilt when the EOP or leap-second table changes (orbitcal data update).
    key = (step_s, tables_epoch(), hashlib.sha1(k.tobytes()).digest())
    with _GRID_LOCK:
        hit = _GRID_CACHE.get(key)
        if hit is not None:
            _GRID_CACHE.move_to_end(key)
            return hit
    value = _grid_nodes(k, step_s)
    with _GRID_LOCK:
        _GRID_CACHE[key] = value
        while len(_GRID_CACHE) > _GRID_CACHE_SIZE:
            _GRID_CACHE.popitem(last=False)
    return value


def _slow_parts(
    tt_s: FloatArray, step_s: float, *, need_c: bool = True
) -> tuple[FloatArray | None, FloatArray | None, FloatArray]:
    """Interpolated C (N,3,3), W (N,3,3) or None when W = I, and ΔT = TT − UT1 [s] (N,)."""
    x = tt_s / step_s
    k = np.floor(x)
    frac = x - k
    k_int = k.astype(np.int64)
    # Evaluate only the grid nodes the samples need, in one Skyfield call (cached).
    needed = np.unique(np.concatenate([k_int, k_int + 1]))
    c_all, w_all, dt_all = _grid_cached(needed, step_s)
    i0 = np.searchsorted(needed, k_int)
    i1 = i0 + 1
    dt_n = dt_all[i0] + (dt_all[i1] - dt_all[i0]) * frac
    c_n = None
    if need_c:
        c_n = c_all[i0] + (c_all[i1] - c_all[i0]) * frac[:, None, None]
    w_n = None
    if not np.all(w_all == np.eye(3)):
        w_n = w_all[i0] + (w_all[i1] - w_all[i0]) * frac[:, None, None]
    return c_n, w_n, dt_n


def gcrs_to_itrs_matrix(t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S) -> FloatArray:
    """Rotation matrices GCRS → ITRS (IAU 2006/2000A, CIO based), ``r_itrs = M @ r_gcrs``.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s], 1972 or later.
    step_s : float, keyword-only
        Grid step [s] for the slowly varying celestial-to-intermediate matrix, polar motion and
        ΔT, which are interpolated linearly (error < 1e-5 arcsec at 1 h).

    Returns
    -------
    ndarray, shape (N, 3, 3)
        ``W(t) · R3(ERA(t)) · C(t)``, equal to Skyfield's ``itrs.rotation_at(t)`` to < 1 mas.
    """
    t = _times(t_utc_s)
    if t.size == 0:
        return np.empty((0, 3, 3))
    if not np.all(np.isfinite(t)):
        raise OutOfRangeError("t_utc_s must be finite (and on or after 1972-01-01)")
    tt_s = _tt_s(t)
    if not np.all(np.isfinite(tt_s)):
        raise OutOfRangeError("t_utc_s before 1972-01-01 is outside the leap-second table")
    c, w, delta_t_s = _slow_parts(tt_s, float(step_s))
    assert c is not None
    era = earth_rotation_angle_rad(tt_s - delta_t_s)
    m = _r3_rows(era, c)
    if w is not None:
        m = np.einsum("nij,njk->nik", w, m)
    return m


def gcrs_to_itrs(
    v_gcrs: npt.ArrayLike, t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S
) -> FloatArray:
    """Rotate vectors GCRS → ITRS (positions [km], fields [nT], ...; no velocity terms).

    Parameters
    ----------
    v_gcrs : array_like, shape (N, 3) or (3,)
        Vectors in GCRS (x to the equinox of J2000 / ICRS origin, z to the celestial pole).
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].

    Returns
    -------
    ndarray, shape (N, 3)
        The vectors in ITRS, same unit.
    """
    return _mv(gcrs_to_itrs_matrix(t_utc_s, step_s=step_s), _vec(v_gcrs, "v_gcrs"))


def itrs_to_gcrs(
    v_itrs: npt.ArrayLike, t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S
) -> FloatArray:
    """Rotate vectors ITRS → GCRS (inverse of :func:`gcrs_to_itrs`); shapes as there."""
    return _mtv(gcrs_to_itrs_matrix(t_utc_s, step_s=step_s), _vec(v_itrs, "v_itrs"))


# --- TEME ---------------------------------------------------------------------------------------


def _ut1_and_w(t: FloatArray, step_s: float) -> tuple[FloatArray, FloatArray | None]:
    """UT1 as a POSIX-style count [s] and polar motion W (None when W = I)."""
    tt_s = _tt_s(t)
    if not np.all(np.isfinite(tt_s)):
        raise OutOfRangeError("t_utc_s must be finite and on or after 1972-01-01")
    if t.size == 0:
        return tt_s, None
    _, w, delta_t_s = _slow_parts(tt_s, step_s, need_c=False)
    return tt_s - delta_t_s, w


def teme_to_itrs_matrix(t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S) -> FloatArray:
    """Rotation matrices TEME → ITRS, ``W · R3(θ_GMST82(UT1))``, shape (N, 3, 3)."""
    t = _times(t_utc_s)
    t_ut1_s, w = _ut1_and_w(t, float(step_s))
    theta, _ = gmst82_rad(t_ut1_s)
    m = _r3_rows(theta, np.broadcast_to(np.eye(3), (t.size, 3, 3)).copy())
    if w is not None:
        m = np.einsum("nij,njk->nik", w, m)
    return m


def teme_to_itrs(
    r_teme_km: npt.ArrayLike,
    v_teme_km_s: npt.ArrayLike,
    t_utc_s: npt.ArrayLike,
    *,
    step_s: float = _DEFAULT_STEP_S,
) -> tuple[FloatArray, FloatArray]:
    """TEME (SGP4's frame) → ITRS, positions and velocities (Vallado et al. 2006, appendix C).

    Parameters
    ----------
    r_teme_km : array_like, shape (N, 3)
        Positions in TEME [km].
    v_teme_km_s : array_like, shape (N, 3)
        Velocities in TEME [km/s].
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].

    Returns
    -------
    r_itrs_km : ndarray, shape (N, 3)
        Positions in ITRS [km].
    v_itrs_km_s : ndarray, shape (N, 3)
        Velocities relative to the rotating ITRS [km/s]: ``W (R3(θ) v − θ̇ ẑ × R3(θ) r)``.
    """
    t = _times(t_utc_s)
    r = _vec(r_teme_km, "r_teme_km")
    v = _vec(v_teme_km_s, "v_teme_km_s")
    t_ut1_s, w = _ut1_and_w(t, float(step_s))
    theta, theta_dot = gmst82_rad(t_ut1_s)
    c, s = np.cos(theta), np.sin(theta)
    r, v = np.broadcast_arrays(r, v)
    r_pef = np.stack([c * r[..., 0] + s * r[..., 1], -s * r[..., 0] + c * r[..., 1], r[..., 2]], -1)
    v_rot = np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], v[..., 2]], -1)
    # − ω × r with ω = θ̇ ẑ:  (θ̇ y, −θ̇ x, 0)
    v_pef = v_rot + np.stack(
        [theta_dot * r_pef[..., 1], -theta_dot * r_pef[..., 0], np.zeros_like(theta)], -1
    )
    if w is None:
        return r_pef, v_pef
    return _mv(w, r_pef), _mv(w, v_pef)


def itrs_to_teme(
    r_itrs_km: npt.ArrayLike,
    v_itrs_km_s: npt.ArrayLike,
    t_utc_s: npt.ArrayLike,
    *,
    step_s: float = _DEFAULT_STEP_S,
) -> tuple[FloatArray, FloatArray]:
    """ITRS → TEME, positions [km] and velocities [km/s] (inverse of :func:`teme_to_itrs`)."""
    t = _times(t_utc_s)
    r = _vec(r_itrs_km, "r_itrs_km")
    v = _vec(v_itrs_km_s, "v_itrs_km_s")
    t_ut1_s, w = _ut1_and_w(t, float(step_s))
    theta, theta_dot = gmst82_rad(t_ut1_s)
    r, v = np.broadcast_arrays(r, v)
    if w is not None:
        r, v = _mtv(w, r), _mtv(w, v)
    v_rot = v - np.stack([theta_dot * r[..., 1], -theta_dot * r[..., 0], np.zeros_like(theta)], -1)
    c, s = np.cos(theta), np.sin(theta)
    r_teme = np.stack([c * r[..., 0] - s * r[..., 1], s * r[..., 0] + c * r[..., 1], r[..., 2]], -1)
    v_teme = np.stack(
        [
            c * v_rot[..., 0] - s * v_rot[..., 1],
            s * v_rot[..., 0] + c * v_rot[..., 1],
            v_rot[..., 2],
        ],
        -1,
    )
    return r_teme, v_teme


def gcrs_to_teme_matrix(t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S) -> FloatArray:
    """Rotation matrices GCRS → TEME, ``R3(θ_GMST82 − ERA) · C`` (Earth rotation cancels).

    Equal to Skyfield's ``sgp4lib.TEME.rotation_at(t)``; shape (N, 3, 3).
    """
    t = _times(t_utc_s)
    if t.size == 0:
        return np.empty((0, 3, 3))
    tt_s = _tt_s(t)
    if not np.all(np.isfinite(tt_s)):
        raise OutOfRangeError("t_utc_s must be finite and on or after 1972-01-01")
    c, _, delta_t_s = _slow_parts(tt_s, float(step_s))
    assert c is not None
    t_ut1_s = tt_s - delta_t_s
    theta, _ = gmst82_rad(t_ut1_s)
    return _r3_rows(earth_rotation_angle_rad(t_ut1_s) - theta, c)


def gcrs_to_teme(
    v_gcrs: npt.ArrayLike, t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S
) -> FloatArray:
    """Rotate vectors GCRS → TEME (positions [km] or, both frames being quasi-inertial,
    velocities [km/s]; the frames' own precession-nutation rate, < 1e-11 rad/s, is neglected).

    Shapes: ``v_gcrs`` (N, 3) or (3,), ``t_utc_s`` (N,) → (N, 3).
    """
    return _mv(gcrs_to_teme_matrix(t_utc_s, step_s=step_s), _vec(v_gcrs, "v_gcrs"))


def teme_to_gcrs(
    v_teme: npt.ArrayLike, t_utc_s: npt.ArrayLike, *, step_s: float = _DEFAULT_STEP_S
) -> FloatArray:
    """Rotate vectors TEME → GCRS (inverse of :func:`gcrs_to_teme`); shapes as there."""
    return _mtv(gcrs_to_teme_matrix(t_utc_s, step_s=step_s), _vec(v_teme, "v_teme"))


# --- spherical, geodetic ------------------------------------------------------------------------


def itrs_to_spherical(r_itrs_km: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """ITRS Cartesian → geocentric spherical coordinates.

    Parameters
    ----------
    r_itrs_km : array_like, shape (N, 3)
        Positions in ITRS [km].

    Returns
    -------
    radius_km : ndarray, shape (N,)
        Geocentric distance [km].
    colat_deg : ndarray, shape (N,)
        Geocentric colatitude [deg], 0 at the north pole, 180 at the south pole.
    lon_deg : ndarray, shape (N,)
        Longitude [deg] east of Greenwich, in (−180, 180].
    """
    r = _vec(r_itrs_km, "r_itrs_km")
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    rho = np.hypot(x, y)
    radius = np.hypot(rho, z)
    colat = np.degrees(np.arctan2(rho, z))
    lon = np.degrees(np.arctan2(y, x))
    return radius, colat, lon


def spherical_to_itrs(
    radius_km: npt.ArrayLike, colat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike
) -> FloatArray:
    """Geocentric spherical (radius [km], colatitude [deg], longitude [deg]) → ITRS [km], (N, 3)."""
    radius = np.asarray(radius_km, dtype=np.float64)
    theta = np.radians(np.asarray(colat_deg, dtype=np.float64))
    phi = np.radians(np.asarray(lon_deg, dtype=np.float64))
    st = np.sin(theta)
    return np.stack(
        np.broadcast_arrays(
            radius * st * np.cos(phi), radius * st * np.sin(phi), radius * np.cos(theta)
        ),
        axis=-1,
    )


def geodetic_to_itrs(
    lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, height_km: npt.ArrayLike
) -> FloatArray:
    """WGS84 geodetic latitude [deg], longitude [deg], height [km] → ITRS [km], shape (N, 3)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    h = np.asarray(height_km, dtype=np.float64)
    sl, cl = np.sin(lat), np.cos(lat)
    n = WGS84_A_KM / np.sqrt(1.0 - _WGS84_E2 * sl * sl)
    return np.stack(
        np.broadcast_arrays(
            (n + h) * cl * np.cos(lon), (n + h) * cl * np.sin(lon), (n * (1.0 - _WGS84_E2) + h) * sl
        ),
        axis=-1,
    )


def itrs_to_geodetic(r_itrs_km: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """ITRS [km] → WGS84 geodetic latitude [deg], longitude [deg], height [km].

    Bowring's method with three Newton-like refinements (exact to < 1 µm for |h| < 10⁴ km).

    Returns
    -------
    lat_deg, lon_deg, height_km : ndarray, shape (N,)
    """
    r = _vec(r_itrs_km, "r_itrs_km")
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    ep2 = _WGS84_E2 / (1.0 - _WGS84_E2)
    # Bowring (1976) initial parametric latitude, then iterate the exact relation.
    beta = np.arctan2(z * WGS84_A_KM, p * _WGS84_B_KM)
    lat = np.arctan2(
        z + ep2 * _WGS84_B_KM * np.sin(beta) ** 3, p - _WGS84_E2 * WGS84_A_KM * np.cos(beta) ** 3
    )
    for _ in range(3):
        beta = np.arctan2((1.0 - _WGS84_F) * np.sin(lat), np.cos(lat))
        lat = np.arctan2(
            z + ep2 * _WGS84_B_KM * np.sin(beta) ** 3,
            p - _WGS84_E2 * WGS84_A_KM * np.cos(beta) ** 3,
        )
    sl, cl = np.sin(lat), np.cos(lat)
    n = WGS84_A_KM / np.sqrt(1.0 - _WGS84_E2 * sl * sl)
    # Height, well conditioned at all latitudes.
    h = p * cl + z * sl - WGS84_A_KM * WGS84_A_KM / n
    return np.degrees(lat), np.degrees(lon), h


# --- NEC ----------------------------------------------------------------------------------------


def nec_basis_itrs(r_itrs_km: npt.ArrayLike) -> FloatArray:
    """Unit vectors North, East, Centre at positions, in ITRS, as rows: shape (N, 3, 3).

    ``basis[n, 0]`` is North (−θ̂), ``basis[n, 1]`` East (φ̂), ``basis[n, 2]`` Centre (−r̂), all
    geocentric. ``v_nec = basis @ v_itrs``. At the poles (ρ = 0) φ is taken as 0.
    """
    r = _vec(r_itrs_km, "r_itrs_km")
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    rho = np.hypot(x, y)
    radius = np.hypot(rho, z)
    safe_rho = np.where(rho > 0.0, rho, 1.0)
    cp = np.where(rho > 0.0, x / safe_rho, 1.0)
    sp = np.where(rho > 0.0, y / safe_rho, 0.0)
    ct = z / radius
    st = rho / radius
    zero = np.zeros_like(ct)
    north = np.stack([-ct * cp, -ct * sp, st], -1)
    east = np.stack([-sp, cp, zero], -1)
    centre = np.stack([-st * cp, -st * sp, -ct], -1)
    return np.stack([north, east, centre], axis=-2)


def itrs_to_nec(v_itrs: npt.ArrayLike, r_itrs_km: npt.ArrayLike) -> FloatArray:
    """Vectors in ITRS → local geocentric North, East, Centre components at ``r_itrs_km``.

    Parameters
    ----------
    v_itrs : array_like, shape (N, 3)
        Vectors in ITRS (e.g. ``b_itrs_nt`` [nT]).
    r_itrs_km : array_like, shape (N, 3)
        Positions where the NEC frames are attached, ITRS [km].

    Returns
    -------
    ndarray, shape (N, 3)
        ``(N, E, C)`` components, same unit; C is positive towards the Earth's centre.
    """
    return _mv(nec_basis_itrs(r_itrs_km), _vec(v_itrs, "v_itrs"))


def nec_to_itrs(v_nec: npt.ArrayLike, r_itrs_km: npt.ArrayLike) -> FloatArray:
    """Local geocentric North, East, Centre components → ITRS (inverse of :func:`itrs_to_nec`)."""
    return _mtv(nec_basis_itrs(r_itrs_km), _vec(v_nec, "v_nec"))
