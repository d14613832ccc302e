"""Physical plausibility of a magnetometer table and of a calibration fitted on it (issue 44).

A table can parse and still not be a magnetometer in nT along the given orbit: a file in Tesla,
Gauss or µT, the elements of another spacecraft, a stuck or swapped axis. A linear fit absorbs
all of them (M ≈ 1e9 for Tesla) and reports a small or meaningless held-out error, so every entry
point (library, CLI, HTTP ingest, retraining, promotion, Yamcs push) asks this module first.

Bounds, each a physical range and not a tuning knob:

* The Earth's main field at the surface is 22,000-67,000 nT (IGRF; rounded out to
  :data:`SURFACE_FIELD_NT`), falling as a dipole, ``(R_E / r)^3``.
* A raw magnetometer differs from the field by its gains (a few per cent to tens of per cent)
  and offsets (up to a few thousand nT): :data:`RAW_SCALE_TOLERANCE` allows a factor of 5 either
  way, while a wrong unit is a factor of 1e3 (µT), 1e5 (Gauss) or 1e9 (Tesla).
* A calibration's gain, the singular values of ``M``, within :data:`GAIN_BOUNDS` (0.5-2): a
  sensor needing more is not in nT or not a magnetometer; ``det(M) < 0`` is a reflection, which
  no mounting produces: two axes are swapped or one inverted.
* Held-out error at most :data:`MAX_HOLDOUT_RMS_NT`: more is no calibration of the Earth's field.
* The orbit matches the data when the measured magnitude follows the reference magnitude along
  the track: the linear fit ``|b_raw| ≈ a |B_ref| + c`` leaves at most
  :data:`MAX_MAGNITUDE_MISFIT` of the reference magnitude's spread. Wrong elements (Swarm A's for
  ISS telemetry) put the reference field somewhere else; the misfit then approaches 1.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError

__all__ = [
    "GAIN_BOUNDS",
    "MAX_HOLDOUT_RMS_NT",
    "MAX_MAGNITUDE_MISFIT",
    "RAW_SCALE_TOLERANCE",
    "SURFACE_FIELD_NT",
    "ImplausibleInputError",
    "calibration_problem",
    "check_table",
    "dipole_field_bounds_nt",
    "document_problem",
    "elements_radius_km",
    "field_scale_problem",
    "orbit_mismatch_problem",
    "table_radius_km",
]

#: Mean Earth radius [km] (IGRF reference radius 6371.2 km).
EARTH_RADIUS_KM = 6371.2
#: The main field's magnitude at the surface, rounded out [nT] (IGRF-14: ~22,000 in the South
#: Atlantic Anomaly to ~67,000 near the south magnetic pole).
SURFACE_FIELD_NT = (18_000.0, 68_000.0)
#: A raw reading may differ from the field by this factor either way (gains, offsets) [-].
RAW_SCALE_TOLERANCE = 5.0
#: Singular values of a calibration's M allowed for a magnetometer in nT [-].
GAIN_BOUNDS = (0.5, 2.0)
#: The largest held-out RMS a calibration of the Earth's field may leave [nT].
MAX_HOLDOUT_RMS_NT = 5_000.0
#: The largest share of the reference magnitude's spread the measured magnitude may miss [-].
MAX_MAGNITUDE_MISFIT = 0.5
#: Units a table is commonly (and wrongly) written in, and the factor to nT.
_UNITS = (
    ("Tesla", 1e9, "1e9"),
    ("Gauss", 1e5, "1e5"),
    ("mG (milligauss)", 1e2, "100"),
    ("µT", 1e3, "1e3"),
    ("pT", 1e-3, "1e-3"),
)


class ImplausibleInputError(BadInputError):
    """A table or calibration that parses but cannot be a magnetometer in nT on this orbit."""


def dipole_field_bounds_nt(r_km: float) -> tuple[float, float]:
    """The Earth's main-field magnitude range at geocentric distance ``r_km`` [nT] (a dipole
    falling as ``(R_E / r)^3`` from :data:`SURFACE_FIELD_NT`)."""
    k = (EARTH_RADIUS_KM / max(float(r_km), EARTH_RADIUS_KM)) ** 3
    return SURFACE_FIELD_NT[0] * k, SURFACE_FIELD_NT[1] * k


#: Earth's gravitational parameter [km^3/s^2] (WGS-72, as SGP4).
_MU_KM3_S2 = 398_600.8


def mean_motion_radius_km(mean_motion_rev_per_day: float) -> float:
    """The semi-major axis of an orbit with this mean motion [km] (Kepler's third law)."""
    n_rad_s = float(mean_motion_rev_per_day) * 2.0 * np.pi / 86_400.0
    return float((_MU_KM3_S2 / n_rad_s**2) ** (1.0 / 3.0))


def elements_radius_km(tle: str | None, omm: Mapping[str, Any] | None) -> float | None:
    """The semi-major axis from a TLE's line 2 (mean motion, columns 53-63) or an OMM's
    ``MEAN_MOTION`` [km]; None when neither gives one."""
    try:
        if omm and "MEAN_MOTION" in omm:
            return mean_motion_radius_km(float(omm["MEAN_MOTION"]))
        for line in (tle or "").splitlines():
            if line.startswith("2 ") and len(line) >= 63:
                return mean_motion_radius_km(float(line[52:63]))
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return None


def table_radius_km(telemetry: Any) -> float | None:
    """The median geocentric distance of a table's positions [km], None without positions."""
    r = getattr(telemetry, "r_itrs_km", None)
    if r is None or len(r) == 0:
        return None
    return float(np.median(np.linalg.norm(np.asarray(r, dtype=np.float64), axis=1)))


def field_scale_problem(
    b_raw_nt: FloatArray,
    *,
    b_ref_mag_nt: FloatArray | None = None,
    r_km: float | None = None,
) -> str | None:
    """Why the table's median |B| cannot be the Earth's field in nT, or None.

    The expected magnitude is the reference field's median along the orbit when given, else the
    dipole range at ``r_km``, else the range from the surface to geostationary orbit.
    """
    b = np.asarray(b_raw_nt, dtype=np.float64)
    mag = np.linalg.norm(b[np.all(np.isfinite(b), axis=1)], axis=1)
    if mag.size == 0:
        return None
    median = float(np.median(mag))
    if b_ref_mag_nt is not None and np.size(b_ref_mag_nt):
        ref = float(np.median(np.asarray(b_ref_mag_nt, dtype=np.float64)))
        lo, hi = ref / RAW_SCALE_TOLERANCE, ref * RAW_SCALE_TOLERANCE
        expected = f"the reference field along the orbit has median {ref:,.0f} nT"
        centre = ref
    else:
        centre = float(np.sqrt(np.prod(dipole_field_bounds_nt(r_km or EARTH_RADIUS_KM + 500.0))))
        d_lo, d_hi = dipole_field_bounds_nt(r_km if r_km is not None else EARTH_RADIUS_KM)
        if r_km is None:
            d_lo = dipole_field_bounds_nt(42_164.0)[0]  # down to geostationary orbit
        lo, hi = d_lo / RAW_SCALE_TOLERANCE, d_hi * RAW_SCALE_TOLERANCE
        where = "between the surface and GEO" if r_km is None else f"at {r_km - 6371.2:,.0f} km"
        expected = f"the Earth's field {where} is {d_lo:,.0f}-{d_hi:,.0f} nT"
    if lo <= median <= hi:
        return None
    hint = ""
    fits = [u for u in _UNITS if median > 0 and lo <= median * u[1] <= hi]
    if fits:  # the unit landing nearest the expected field (µT and mG can both fit the range;
        # without positions, the expected field is that of a low orbit, 500 km)
        unit, _, written = min(fits, key=lambda u: abs(np.log(median * u[1] / centre)))
        hint = f"looks like {unit}: scale by {written}; "
    return (
        f"the field is not in nT: {hint}the table's median |B| is {median:.6g} nT but {expected} "
        f"(a raw magnetometer may be off by up to ×{RAW_SCALE_TOLERANCE:g})"
    )


def orbit_mismatch_problem(b_raw_nt: FloatArray, b_ref_mag_nt: FloatArray) -> str | None:
    """Why the reference field along these elements cannot be the field measured, or None.

    Fits ``|b_raw| ≈ a |B_ref| + c`` by least squares; the misfit is the residual RMS over the
    spread (standard deviation) of ``|B_ref|``. Checked only when the reference magnitude varies
    by more than 5 % along the table (a short span says nothing).
    """
    b = np.asarray(b_raw_nt, dtype=np.float64)
    ref = np.asarray(b_ref_mag_nt, dtype=np.float64)
    ok = np.all(np.isfinite(b), axis=1) & np.isfinite(ref)
    mag, ref = np.linalg.norm(b[ok], axis=1), ref[ok]
    if mag.size < 20 or np.std(ref) < 0.05 * np.mean(ref) or np.std(mag) == 0:
        return None
    design = np.column_stack([ref, np.ones_like(ref)])
    coef, *_ = np.linalg.lstsq(design, mag, rcond=None)
    misfit = float(np.sqrt(np.mean((mag - design @ coef) ** 2)) / np.std(ref))
    corr = float(np.corrcoef(mag, ref)[0, 1])
    if misfit <= MAX_MAGNITUDE_MISFIT and coef[0] > 0:
        return None
    return (
        f"the orbit elements do not match the data: the measured |B| does not follow the "
        f"reference field's magnitude along these elements (correlation {corr:.2f}, misfit "
        f"{misfit:.2f} of its spread, limit {MAX_MAGNITUDE_MISFIT:g}); are the elements "
        "(TLE/OMM, --norad) those of this spacecraft, and the times UTC?"
    )


def check_table(
    b_raw_nt: FloatArray,
    *,
    b_ref_mag_nt: FloatArray | None = None,
    r_km: float | None = None,
    orbit: bool = True,
) -> None:
    """Raise :class:`ImplausibleInputError` for a table in the wrong unit or (``orbit``, with
    the reference magnitude) on the elements of another spacecraft."""
    why = field_scale_problem(b_raw_nt, b_ref_mag_nt=b_ref_mag_nt, r_km=r_km)
    if why is None and orbit and b_ref_mag_nt is not None:
        why = orbit_mismatch_problem(b_raw_nt, b_ref_mag_nt)
    if why is not None:
        raise ImplausibleInputError(why, field="b_x,b_y,b_z")


def calibration_problem(m: Any, holdout_rms_nt: float | None) -> str | None:
    """Why a calibration with soft-iron matrix ``m`` and this held-out RMS cannot be a
    magnetometer's in nT, or None (gain outside :data:`GAIN_BOUNDS`, a reflection, held-out
    RMS over :data:`MAX_HOLDOUT_RMS_NT`)."""
    problems = []
    try:
        matrix = np.asarray(m, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        matrix = None
    if matrix is not None and np.all(np.isfinite(matrix)):
        s = np.linalg.svd(matrix, compute_uv=False)
        if s.min() < GAIN_BOUNDS[0] or s.max() > GAIN_BOUNDS[1]:
            problems.append(
                f"its gains (singular values of M) are {s.min():.3g}-{s.max():.3g}, outside "
                f"{GAIN_BOUNDS[0]:g}-{GAIN_BOUNDS[1]:g} for a magnetometer in nT (a table in "
                "another unit, or not a magnetometer)"
            )
        if np.linalg.det(matrix) < 0:
            problems.append(
                "det(M) < 0: it mirrors the axes, which no mounting does: two sensor axes are "
                "swapped or one is inverted (check the b_x, b_y, b_z mapping)"
            )
    elif matrix is not None:
        problems.append("M is not finite")
    if holdout_rms_nt is not None and holdout_rms_nt > MAX_HOLDOUT_RMS_NT:  # NaN: not known
        problems.append(
            f"its held-out RMS {holdout_rms_nt:,.0f} nT exceeds {MAX_HOLDOUT_RMS_NT:,.0f} nT"
        )
    return "; ".join(problems) or None


def document_problem(
    document: Mapping[str, Any], *, holdout_rms_nt: float | None = None
) -> str | None:
    """:func:`calibration_problem` of a section-4 document: its ``linear.M`` and its metrics'
    held-out RMS, or ``holdout_rms_nt`` when the caller measured it (a promotion)."""
    linear = document.get("linear") or {}
    metrics = document.get("metrics") or {}
    rms = holdout_rms_nt if holdout_rms_nt is not None else metrics.get("holdout_rms_nt")
    return calibration_problem(
        linear.get("M") if isinstance(linear, Mapping) else None,
        float(rms) if isinstance(rms, int | float) else None,
    )
