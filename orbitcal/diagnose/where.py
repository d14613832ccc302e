"""Where the gap lies: the residual by axis, vector vs scalar, region, condition and time.

All statistics are of a residual ``r = b_raw - (A b_ref + o)`` (sensor axes ~ body axes) [nT]:
by default the 12-parameter calibration fitted on the training blocks, evaluated on every sample,
so the bands cover the whole ground track; ``axis_rms_nt`` and the vector/scalar split are given on
the held-out blocks as in CONTRACT section 5.

* *scalar* residual: the component along the reference field, what an attitude-free (|B|) check
  sees; *perpendicular*: the rest, where attitude errors and field-aligned currents live.
* magnetic latitude: centred dipole (:func:`orbitcal.geomag.magnetic_latitude_deg`, IGRF-14 2025.0).
* local time: mean solar local time from longitude and UTC [h].
* orbit phase: argument-of-latitude-like phase from the track [deg].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.metrics import norm_rms_nt, rms_nt

__all__ = ["MLAT_BANDS_DEG", "local_time_h", "where_analysis"]


#: |magnetic latitude| bands [deg].
MLAT_BANDS_DEG: tuple[tuple[float, float], ...] = (
    (0.0, 30.0),
    (30.0, 50.0),
    (50.0, 60.0),
    (60.0, 70.0),
    (70.0, 90.0),
)


def local_time_h(t_utc_s: FloatArray, r_itrs_km: FloatArray) -> FloatArray:
    """Mean solar local time [h] in [0, 24): UTC hour plus east longitude / 15."""
    lon_deg = np.degrees(np.arctan2(r_itrs_km[:, 1], r_itrs_km[:, 0]))
    return np.asarray(np.mod((t_utc_s % 86400.0) / 3600.0 + lon_deg / 15.0, 24.0))


def _split(r: FloatArray, b_hat: FloatArray) -> tuple[FloatArray, FloatArray]:
    par = np.sum(r * b_hat, axis=1)
    perp = r - par[:, None] * b_hat
    return par, perp


def _stats(r: FloatArray, b_hat: FloatArray, mask: BoolArray) -> dict[str, float | int]:
    par, perp = _split(r[mask], b_hat[mask])
    return {
        "n": int(mask.sum()),
        "rms_nt": round(norm_rms_nt(r[mask]), 3),
        "scalar_rms_nt": round(rms_nt(par), 3),
        "perpendicular_rms_nt": round(norm_rms_nt(perp), 3),
    }


def _dominant_periods(
    t_s: FloatArray, r: FloatArray, *, n_peaks: int = 3
) -> list[dict[str, float]]:
    """Strongest periods [s] of the residual (resampled, Hann window) and amplitudes [nT]."""
    if t_s.size < 16:
        return []
    step = float(np.median(np.diff(t_s)))
    grid = np.arange(t_s[0], t_s[-1], step)
    out: list[dict[str, float]] = []
    spec_total = np.zeros(grid.size // 2 + 1)
    for k in range(3):
        y = np.interp(grid, t_s, r[:, k])
        y = (y - y.mean()) * np.hanning(y.size)
        spec_total += np.abs(np.fft.rfft(y)) ** 2
    freqs = np.fft.rfftfreq(grid.size, step)
    spec = spec_total.copy()
    spec[:2] = 0.0  # drop the mean and the record-length trend
    norm = 2.0 / max(np.sum(np.hanning(grid.size)), 1e-12)
    for _ in range(n_peaks):
        i = int(np.argmax(spec))
        if spec[i] <= 0:
            break
        out.append(
            {
                "period_s": round(float(1.0 / freqs[i]), 1),
                "amplitude_nt": round(float(np.sqrt(spec[i]) * norm), 3),
            }
        )
        spec[max(0, i - 2) : i + 3] = 0.0
    return out


def where_analysis(
    data: DiagnosisData,
    residual_nt: FloatArray,
    *,
    holdout: BoolArray,
    n_time_blocks: int = 10,
) -> dict[str, Any]:
    """Where the residual lies (the ``where`` object of the CONTRACT section-5 report).

    Parameters
    ----------
    data : DiagnosisData
    residual_nt : ndarray, shape (N, 3)
        Residual per sample, sensor axes [nT].
    holdout : ndarray of bool, shape (N,)
        Held-out samples (``axis_rms_nt`` and the vector/scalar split are computed there).
    n_time_blocks : int
        Equal-duration blocks for the time series.

    Returns
    -------
    dict
        ``axis_rms_nt`` [x, y, z], ``rms_nt`` (per component), ``norm_rms_nt``, ``scalar_rms_nt``,
        ``perpendicular_rms_nt``, ``scalar_to_vector``, ``magnetic_latitude``, ``sunlit_eclipse``,
        ``local_time``, ``orbit_phase``, ``time``, ``frequency``, ``concentration`` (the band and
        condition holding the largest excess).
    """
    r = residual_nt
    b_hat = data.b_hat_body
    h = holdout
    par_h, perp_h = _split(r[h], b_hat[h])
    out: dict[str, Any] = {
        "residual": "12-parameter calibration fitted on the training blocks",
        "axis_rms_nt": [round(rms_nt(r[h, k]), 3) for k in range(3)],
        "rms_nt": round(rms_nt(r[h]), 3),
        "norm_rms_nt": round(norm_rms_nt(r[h]), 3),
        "scalar_rms_nt": round(rms_nt(par_h), 3),
        "perpendicular_rms_nt": round(norm_rms_nt(perp_h), 3),
    }
    out["scalar_to_vector"] = round(out["scalar_rms_nt"] / max(out["norm_rms_nt"], 1e-12), 4)

    bands = _latitude_bands(data, r, b_hat)
    out["magnetic_latitude"] = bands
    lit = _sunlit(data)
    if lit is not None:
        out["sunlit_eclipse"] = {
            "sunlit": _stats(r, b_hat, lit),
            "eclipse": _stats(r, b_hat, ~lit),
        }
    out["local_time"], out["orbit_phase"] = _local_time_and_phase(data, r, b_hat)
    out["time"] = _time_blocks(data, r, b_hat, h, n_time_blocks)
    out["frequency"] = _dominant_periods(data.t_utc_s, r)
    out["concentration"] = _concentration(r, bands, out.get("sunlit_eclipse"))
    return out


def _latitude_bands(data: DiagnosisData, r: FloatArray, b_hat: FloatArray) -> list[dict[str, Any]]:
    """The residual's statistics per band of |magnetic latitude| (bands without samples left
    out)."""
    amlat = np.abs(data.mlat_deg)
    bands: list[dict[str, Any]] = []
    for lo, hi in MLAT_BANDS_DEG:
        m = (amlat >= lo) & (amlat < hi if hi < 90 else amlat <= hi)
        if m.any():
            bands.append({"band_deg": [lo, hi], **_stats(r, b_hat, m)})
    return bands


def _sunlit(data: DiagnosisData) -> BoolArray | None:
    """Sunlit samples (more than half the solar disc visible), or None without the Sun."""
    if data.illumination is not None:
        return np.asarray(data.illumination > 0.5)
    if data.sunlit is not None:
        return np.asarray(data.sunlit, dtype=bool)
    return None


def _local_time_and_phase(
    data: DiagnosisData, r: FloatArray, b_hat: FloatArray
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The residual's statistics per 3 h of local time and per 45 deg of orbit phase."""
    lt = local_time_h(data.t_utc_s, data.r_itrs_km)
    local_time = [
        {"hours": [a, a + 3], **_stats(r, b_hat, (lt >= a) & (lt < a + 3))}
        for a in range(0, 24, 3)
        if np.any((lt >= a) & (lt < a + 3))
    ]
    phase = np.degrees(data.orbit_phase_rad) % 360.0
    orbit_phase = [
        {"deg": [a, a + 45], **_stats(r, b_hat, (phase >= a) & (phase < a + 45))}
        for a in range(0, 360, 45)
        if np.any((phase >= a) & (phase < a + 45))
    ]
    return local_time, orbit_phase


def _time_blocks(
    data: DiagnosisData, r: FloatArray, b_hat: FloatArray, holdout: BoolArray, n_blocks: int
) -> list[dict[str, Any]]:
    """The residual's statistics per equal-duration time block, with whether it is held out."""
    t = data.t_utc_s
    span = float(t[-1] - t[0]) or 1.0
    block = np.minimum(((t - t[0]) / span * n_blocks).astype(int), n_blocks - 1)
    return [
        {
            "block": b,
            "start_utc_s": float(t[block == b][0]),
            "held_out": bool(np.all(holdout[block == b])),
            **_stats(r, b_hat, block == b),
        }
        for b in range(n_blocks)
        if np.any(block == b)
    ]


def _concentration(
    r: FloatArray, bands: list[dict[str, Any]], sunlit_eclipse: dict[str, Any] | None
) -> str:
    """Where the excess is: the band or condition whose mean square most exceeds the overall
    one, if by more than 10 % of the total ("everywhere" otherwise)."""
    overall = norm_rms_nt(r) ** 2
    candidates: list[tuple[float, str]] = []
    for bnd in bands:
        n_b = float(bnd["n"])
        rms_b = float(bnd["rms_nt"])
        lo_b, hi_b = bnd["band_deg"]
        candidates.append((n_b * (rms_b**2 - overall), f"|mlat| {lo_b:g}-{hi_b:g} deg"))
    if sunlit_eclipse is not None:
        for key in ("sunlit", "eclipse"):
            st = sunlit_eclipse[key]
            candidates.append((float(st["n"]) * (float(st["rms_nt"]) ** 2 - overall), key))
    best = max(candidates, default=(0.0, "everywhere"))
    return best[1] if best[0] > 0.1 * overall * r.shape[0] else "everywhere"
