"""The Sun's direction (analytic, no ephemeris file) and the Earth's shadow.

Sun position: the low-precision formula of the Astronomical Almanac (section C, "Low precision
formulas for the Sun"; accurate to 0.01° between 1950 and 2050). It gives the apparent position
in the mean equator and equinox of date; this module uses it as GCRS, which differs by the
precession since J2000 (~0.3° by 2025) — irrelevant for shadow tests (~1 s of eclipse timing at
LEO) and for Sun-driven disturbance fields.

Shadow: the cylindrical model (umbra of a Sun at infinity) and the conical model with penumbra
(Montenbruck & Gill 2000, *Satellite Orbits*, section 3.4.2, eq. 3.85–3.87).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray

__all__ = [
    "AU_KM",
    "R_EARTH_KM",
    "R_SUN_KM",
    "illumination_conical",
    "in_shadow_cylindrical",
    "sun_direction_gcrs",
    "sun_position_gcrs_km",
]


#: Astronomical unit [km] (IAU 2012 resolution B2).
AU_KM = 149_597_870.7
#: Earth equatorial radius [km] (WGS84).
R_EARTH_KM = 6378.137
#: Nominal solar radius [km] (IAU 2015 resolution B3).
R_SUN_KM = 695_700.0
_UNIX_EPOCH_JD = 2_440_587.5
_J2000_JD = 2_451_545.0


def sun_position_gcrs_km(t_utc_s: npt.ArrayLike) -> FloatArray:
    """Geocentric Sun position, Astronomical Almanac low-precision formula.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s] (UTC is used for TT: the 69 s difference moves the Sun 0.0008°).

    Returns
    -------
    ndarray, shape (N, 3)
        Sun position, equatorial (taken as GCRS) x, y, z [km].
    """
    t = np.asarray(t_utc_s, dtype=np.float64)
    n = t / 86400.0 + _UNIX_EPOCH_JD - _J2000_JD  # days from J2000.0
    mean_lon_deg = 280.460 + 0.9856474 * n
    mean_anom_rad = np.deg2rad(357.528 + 0.9856003 * n)
    ecl_lon_rad = np.deg2rad(
        mean_lon_deg + 1.915 * np.sin(mean_anom_rad) + 0.020 * np.sin(2.0 * mean_anom_rad)
    )
    obliquity_rad = np.deg2rad(23.439 - 4.0e-7 * n)
    dist_au = 1.00014 - 0.01671 * np.cos(mean_anom_rad) - 0.00014 * np.cos(2.0 * mean_anom_rad)
    x = np.cos(ecl_lon_rad)
    y = np.cos(obliquity_rad) * np.sin(ecl_lon_rad)
    z = np.sin(obliquity_rad) * np.sin(ecl_lon_rad)
    return np.stack([x, y, z], axis=-1) * (dist_au * AU_KM)[..., None]


def sun_direction_gcrs(t_utc_s: npt.ArrayLike) -> FloatArray:
    """Unit vector from the Earth's centre to the Sun, GCRS, shape (N, 3)."""
    s = sun_position_gcrs_km(t_utc_s)
    return s / np.linalg.norm(s, axis=-1, keepdims=True)


def in_shadow_cylindrical(
    r_gcrs_km: npt.ArrayLike, sun_gcrs: npt.ArrayLike, *, r_earth_km: float = R_EARTH_KM
) -> npt.NDArray[np.bool_]:
    """Cylindrical Earth shadow: behind the Earth and within one Earth radius of the Sun line.

    Parameters
    ----------
    r_gcrs_km : array_like, shape (N, 3)
        Spacecraft position, GCRS [km].
    sun_gcrs : array_like, shape (N, 3) or (3,)
        Sun direction or position, GCRS (only the direction is used).
    r_earth_km : float
        Radius of the shadow cylinder [km].

    Returns
    -------
    ndarray of bool, shape (N,)
        True in shadow.
    """
    r = np.asarray(r_gcrs_km, dtype=np.float64)
    s = np.asarray(sun_gcrs, dtype=np.float64)
    s_hat = s / np.linalg.norm(s, axis=-1, keepdims=True)
    along = np.sum(r * s_hat, axis=-1)
    perp = np.linalg.norm(r - along[..., None] * s_hat, axis=-1)
    return np.asarray((along < 0.0) & (perp < r_earth_km))


def illumination_conical(
    r_gcrs_km: npt.ArrayLike,
    sun_gcrs_km: npt.ArrayLike,
    *,
    r_earth_km: float = R_EARTH_KM,
    r_sun_km: float = R_SUN_KM,
) -> FloatArray:
    """Fraction of the solar disc visible from the spacecraft (conical shadow with penumbra).

    Montenbruck & Gill (2000), eq. 3.85–3.87: apparent radii ``a`` (Sun) and ``b`` (Earth),
    separation ``c`` of their centres; the occulted area of two overlapping discs.

    Parameters
    ----------
    r_gcrs_km : array_like, shape (N, 3)
        Spacecraft position, GCRS [km].
    sun_gcrs_km : array_like, shape (N, 3) or (3,)
        Geocentric Sun position, GCRS [km] (:func:`sun_position_gcrs_km`).

    Returns
    -------
    ndarray, shape (N,)
        1 in full sunlight, 0 in the umbra, between in the penumbra.
    """
    r = np.asarray(r_gcrs_km, dtype=np.float64)
    s = np.asarray(sun_gcrs_km, dtype=np.float64)
    d = s - r  # spacecraft → Sun
    d_norm = np.linalg.norm(d, axis=-1)
    r_norm = np.linalg.norm(r, axis=-1)
    a = np.arcsin(np.clip(r_sun_km / d_norm, -1.0, 1.0))
    b = np.arcsin(np.clip(r_earth_km / r_norm, -1.0, 1.0))
    cos_c = np.sum(-r * d, axis=-1) / (r_norm * d_norm)
    c = np.arccos(np.clip(cos_c, -1.0, 1.0))
    shape = np.broadcast_shapes(a.shape, b.shape, c.shape)
    a, b, c = (np.broadcast_to(v, shape) for v in (a, b, c))
    nu = np.ones(shape)
    umbra = c < b - a
    nu[umbra] = 0.0
    annular = (c < a - b) & ~umbra
    nu[annular] = 1.0 - (b[annular] / a[annular]) ** 2
    partial = (np.abs(a - b) < c) & (c < a + b)
    if np.any(partial):
        ap, bp, cp = a[partial], b[partial], c[partial]
        x = (cp**2 + ap**2 - bp**2) / (2.0 * cp)
        y = np.sqrt(np.maximum(ap**2 - x**2, 0.0))
        area = (
            ap**2 * np.arccos(np.clip(x / ap, -1.0, 1.0))
            + bp**2 * np.arccos(np.clip((cp - x) / bp, -1.0, 1.0))
            - cp * y
        )
        nu[partial] = 1.0 - area / (np.pi * ap**2)
    return nu
