"""Large-scale magnetospheric field driven by the RC index (name ``"RC"``).

A reduced form of the CHAOS external-field parameterisation (Olsen et al. 2014, "The CHAOS-4
geomagnetic field model", GJI 197, eqs. 3–5; Finlay et al. 2020, EPS 72:156, sec. 2.2), keeping
the terms that carry all but a few nT of it at LEO:

- near-magnetospheric (ring-current) field, degree 1 in Solar-Magnetic (SM) coordinates:
  external ``q_1^m,SM = c_m · RC_e(t)`` and its Earth-induced internal counterpart
  ``g_1^m,SM = c_m · RC_i(t)``, ``(c_0, c_1, c_2) = (q10, q11, s11)`` of CHAOS-7;
- far-magnetospheric (magnetopause/tail) field: static external ``q10 = 12.43 nT`` in GSM.

Left out, each ≲ 2 nT at LEO: the CHAOS 30-day baseline corrections Δq10, Δq11, Δs11, the degree-2
SM and GSM terms, and the induced part of the GSM term. ``RC_e``/``RC_i`` are the hourly external
and internal parts of the RC index (DTU's file as installed by ``orbitcal data update``, else the
one shipped with ChaosMagPy, ``chaosmagpy/lib/RC_index.h5``), linearly interpolated as ChaosMagPy
does; the model is valid over the index file's time span.

Frames: SM has z along the northern dipole pole (the centred dipole of ChaosMagPy's
``params.dipole``, IGRF-12 at 2015.0: :data:`CHAOS_SM_DIPOLE_NT`) and the Sun in its x–z plane;
GSM has x towards the Sun and the dipole in its x–z plane. The Sun's direction comes from the
Astronomical Almanac's low-precision formula (0.01°), rotated to ITRS by Greenwich mean sidereal
time — far below the nT level for a field of ≈ 100 nT.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.field._base import (
    FieldRangeError,
    _broadcast_samples,
    require_in_range,
    utc_s_to_mjd2000,
)
from orbitcal.field.synthesis import synth_internal_nec_nt

__all__ = [
    "CHAOS7_Q_GSM_NT",
    "CHAOS7_Q_SM",
    "CHAOS_SM_DIPOLE_NT",
    "RingCurrentField",
    "rc_index_path",
    "ring_current_field",
    "sm_gsm_axes_itrs",
    "sun_direction_itrs",
]


#: CHAOS-7 SM degree-1 response to the RC index (q10, q11, s11) [nT per nT of RC]:
#: ``coeffs_sm[:3]`` of CHAOS-7.mat (ChaosMagPy ``load_CHAOS_matfile``, ancklo/ChaosMagPy
#: docs/source/.static/examples/CHAOS-7.mat).
CHAOS7_Q_SM = (-0.93931258, -0.00407992, -0.00794409)

#: CHAOS-7 static GSM external q10 [nT] (``coeffs_gsm[0]`` of the same file).
CHAOS7_Q_GSM_NT = 12.42987286

#: Centred dipole (g10, g11, h11) [nT] that defines the SM/GSM z axis of the CHAOS external field:
#: IGRF-12 at epoch 2015.0, as ChaosMagPy 0.16 ``basicConfig['params.dipole']`` gives it. Part of
#: the CHAOS parameterisation (its q/s coefficients are fitted in these frames), so it stays at
#: 2015.0; the geomagnetic coordinates of the simulator and diagnosis are :mod:`orbitcal.geomag`.
CHAOS_SM_DIPOLE_NT: tuple[float, float, float] = (-29442.0, -1501.0, 4797.1)

_JD_UNIX_EPOCH = 2440587.5  # Julian date of 1970-01-01T00:00 UTC


def rc_index_path() -> Path:
    """The RC-index file shipped with ChaosMagPy (the fallback; the table in use comes from
    :func:`orbitcal.auxdata.active_table`)."""
    return Path(str(resources.files("chaosmagpy").joinpath("lib", "RC_index.h5")))


def sun_direction_itrs(t_utc_s: FloatArray) -> FloatArray:
    """Unit vector to the Sun in (approximately) ITRS, (N, 3).

    Astronomical Almanac low-precision solar coordinates (section C, "Low precision formulas for
    the Sun", 0.01° for 1950–2050) in the mean equator of date, rotated about z by GMST
    (IAU 1982, Vallado 2013 eq. 3-45, UT1 ≈ UTC). Polar motion and nutation (< 20") are ignored.
    """
    n = np.asarray(t_utc_s, dtype=np.float64) / 86_400.0 + _JD_UNIX_EPOCH - 2451545.0
    mean_lon = np.radians(280.460 + 0.9856474 * n)
    anomaly = np.radians(357.528 + 0.9856003 * n)
    ecl_lon = mean_lon + np.radians(1.915 * np.sin(anomaly) + 0.020 * np.sin(2 * anomaly))
    obliquity = np.radians(23.439 - 0.0000004 * n)
    x = np.cos(ecl_lon)
    y = np.cos(obliquity) * np.sin(ecl_lon)
    z = np.sin(obliquity) * np.sin(ecl_lon)
    tc = n / 36525.0
    gmst = np.radians(
        (280.46061837 + 360.98564736629 * n + 0.000387933 * tc**2 - tc**3 / 38_710_000.0) % 360.0
    )
    c, s = np.cos(gmst), np.sin(gmst)
    return np.stack([c * x + s * y, -s * x + c * y, z], axis=-1)


def sm_gsm_axes_itrs(t_utc_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """SM and GSM unit axes in ITRS: two arrays (N, 3, 3), rows = x, y, z axes."""
    g10, g11, h11 = CHAOS_SM_DIPOLE_NT
    z_sm = -np.array([g11, h11, g10]) / np.linalg.norm([g11, h11, g10])
    sun = sun_direction_itrs(t_utc_s)
    y_sm = np.cross(z_sm, sun)
    y_sm /= np.linalg.norm(y_sm, axis=-1, keepdims=True)
    x_sm = np.cross(y_sm, z_sm)
    z_all = np.broadcast_to(z_sm, sun.shape)
    sm = np.stack([x_sm, y_sm, z_all], axis=-2)
    x_gsm = sun
    y_gsm = y_sm  # z_SM × sun, normalised: the same axis in both frames
    z_gsm = np.cross(x_gsm, y_gsm)
    gsm = np.stack([x_gsm, y_gsm, z_gsm], axis=-2)
    return sm, gsm


def _cart_to_nec(b_cart: FloatArray, colat_rad: FloatArray, lon_rad: FloatArray) -> FloatArray:
    st, ct = np.sin(colat_rad), np.cos(colat_rad)
    sp, cp = np.sin(lon_rad), np.cos(lon_rad)
    bx, by, bz = b_cart[:, 0], b_cart[:, 1], b_cart[:, 2]
    b_r = st * cp * bx + st * sp * by + ct * bz
    b_t = ct * cp * bx + ct * sp * by - st * bz
    b_p = -sp * bx + cp * by
    return np.stack([-b_t, b_p, -b_r], axis=-1)


class RingCurrentField:
    """RC-index-driven magnetospheric field with its induced part (see the module docstring)."""

    def __init__(self, rc_time_mjd2000: FloatArray, rc_e: FloatArray, rc_i: FloatArray) -> None:
        self.rc_time_mjd2000 = np.asarray(rc_time_mjd2000, dtype=np.float64)
        self.rc_e = np.asarray(rc_e, dtype=np.float64)
        self.rc_i = np.asarray(rc_i, dtype=np.float64)

    @property
    def name(self) -> str:
        return "RC"

    @property
    def valid_mjd2000(self) -> tuple[float, float]:
        """Time span of the RC index [MJD2000]."""
        return (float(self.rc_time_mjd2000[0]), float(self.rc_time_mjd2000[-1]))

    def rc_nt(self, t_utc_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """External and internal parts of the RC index at each time [nT]."""
        mjd = utc_s_to_mjd2000(t_utc_s).reshape(-1)
        require_in_range(
            mjd,
            self.valid_mjd2000,
            name="RC (RC index)",
            advice="leave RC out of the field name for these dates",
        )
        return (
            np.interp(mjd, self.rc_time_mjd2000, self.rc_e),
            np.interp(mjd, self.rc_time_mjd2000, self.rc_i),
        )

    def b_nec_nt(
        self,
        t_utc_s: FloatArray,
        radius_km: FloatArray,
        colat_deg: FloatArray,
        lon_deg: FloatArray,
    ) -> FloatArray:
        """Field at each sample, geocentric NEC [nT] (see :class:`orbitcal.field.FieldModel`)."""
        t, radius_km, colat_deg, lon_deg = _broadcast_samples(
            t_utc_s, radius_km, colat_deg, lon_deg
        )
        colat_rad = np.radians(colat_deg)
        lon_rad = np.radians(lon_deg)
        rc_e, rc_i = self.rc_nt(t)
        sm, gsm = sm_gsm_axes_itrs(t)
        q10, q11, s11 = CHAOS7_Q_SM
        # Degree-1 SM coefficients as vectors (q11 x + s11 y + q10 z) in ITRS.
        v_sm = q11 * sm[:, 0] + s11 * sm[:, 1] + q10 * sm[:, 2]  # per nT of RC
        # External degree 1: V = r·q  ->  B = -q (uniform).
        b_ext_cart = -(rc_e[:, None] * v_sm) - CHAOS7_Q_GSM_NT * gsm[:, 2]
        b = _cart_to_nec(b_ext_cart, colat_rad, lon_rad)
        # Induced internal degree 1: GEO Gauss coefficients (g10, g11, h11) = (v_z, v_x, v_y).
        v_int = rc_i[:, None] * v_sm
        blocks = np.stack([v_int[:, 2], v_int[:, 0], np.zeros_like(rc_i), v_int[:, 1]])
        b += synth_internal_nec_nt(blocks.T, radius_km, colat_deg, lon_deg, nmax=1)
        return b

    def __repr__(self) -> str:
        return "RingCurrentField('RC')"


@lru_cache(maxsize=2)
def _rc_field(sha256: str) -> RingCurrentField:
    from orbitcal.auxdata.tables import active_table

    table = active_table("rc_index")
    if table is None or table.sha256 != sha256:  # pragma: no cover - changed between calls
        raise FieldRangeError("the RC index changed while loading; try again")
    d = table.parsed.data
    return RingCurrentField(d["time_mjd2000"], d["rc_e_nt"], d["rc_i_nt"])


def ring_current_field() -> RingCurrentField:
    """The RC-driven field with the RC index in use (:mod:`orbitcal.auxdata`: an installed DTU
    file or, as fallback, the one shipped with ChaosMagPy), loaded once per file."""
    from orbitcal.auxdata.tables import active_table

    table = active_table("rc_index")
    if table is None:  # pragma: no cover - ChaosMagPy ships one
        raise FieldRangeError("no RC index installed: run 'orbitcal data update'")
    return _rc_field(table.sha256)
