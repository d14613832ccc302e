"""The evidence of a diagnosis: the residual before and after the selected effects, binned by the
quantity that drives each effect (temperature, torquer dipole, magnetic latitude, Sun angle, time).

The report carries these curves (``report["evidence"]``, a short JSON list) so that its HTML page
is drawn from the JSON document alone: the command line and the service render the same page.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attribution import Attribution
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.metrics import rms_nt

__all__ = ["DRIVERS", "EFFECT_DRIVER", "Driver", "evidence"]


@dataclass(frozen=True)
class Driver:
    """A quantity an effect follows, computed per sample from the diagnosis data.

    Attributes
    ----------
    key : str
        Its name in the report (``"temperature"``, ``"time_h"``, ...).
    name : str
        A short name for titles.
    label : str
        Axis label with its unit in brackets.
    values : callable
        ``values(data) -> ndarray, shape (N,)`` or None when the data lack it.
    quantile_bins : bool
        Bins of equal sample count (True) or equal width (False; time).
    """

    key: str
    name: str
    label: str
    values: Callable[[DiagnosisData], FloatArray | None]
    quantile_bins: bool = True


def _time_h(data: DiagnosisData) -> FloatArray:
    return np.asarray((data.t_utc_s - data.t_utc_s[0]) / 3600.0)


def _temperature(data: DiagnosisData) -> FloatArray | None:
    return data.hk("temperature")


def _mlat(data: DiagnosisData) -> FloatArray:
    return np.asarray(data.mlat_deg)


def _torquer(data: DiagnosisData) -> FloatArray | None:
    cols = [data.hk(f"mtq_{a}") for a in "xyz"]
    if all(c is None for c in cols):
        from orbitcal.diagnose.design import torquer_currents

        currents = torquer_currents(data)
        if not currents:
            return None
        return np.asarray(np.linalg.norm(np.stack([x for _, x in currents], axis=1), axis=1))
    stacked = np.stack([c if c is not None else np.zeros(data.n) for c in cols], axis=1)
    return np.asarray(np.linalg.norm(stacked, axis=1))


def _sun_angle(data: DiagnosisData) -> FloatArray | None:
    if data.sun_body is None:
        return None
    cos = np.clip(data.sun_body[:, 2] / np.linalg.norm(data.sun_body, axis=1), -1.0, 1.0)
    angle = np.degrees(np.arccos(cos))
    lit = data.illumination > 0.5 if data.illumination is not None else data.sunlit
    if lit is None:
        return np.asarray(angle)
    return np.asarray(np.where(np.asarray(lit, dtype=bool), angle, np.nan))  # eclipse: no Sun


DRIVERS: dict[str, Driver] = {
    d.key: d
    for d in (
        Driver("time_h", "time", "time since the first sample [h]", _time_h, quantile_bins=False),
        Driver(
            "temperature", "temperature", "sensor temperature [°C]", lambda d: d.hk("temperature")
        ),
        Driver(
            "torquer_am2",
            "torquer dipole",
            "magnetorquer dipole |m| [A·m²] (or, without commands, coil currents |I| [A])",
            _torquer,
        ),
        Driver(
            "mlat_deg",
            "magnetic latitude",
            "magnetic latitude [deg]",
            lambda d: np.asarray(d.mlat_deg),
        ),
        Driver(
            "sun_angle_deg",
            "Sun angle",
            "Sun angle from the body +z axis, sunlit only [deg]",
            _sun_angle,
        ),
        Driver(
            "field_rate_nt_s",
            "|dB/dt|",
            "rate of change of the field in the body frame |dB/dt| [nT/s]",
            lambda d: np.asarray(np.linalg.norm(d.db_ref_body_dt_nt_s, axis=1)),
        ),
        Driver(
            "field_nt",
            "|B|",
            "reference field |B| [nT]",
            lambda d: np.asarray(np.linalg.norm(d.b_ref_body_nt, axis=1)),
        ),
    )
}

#: The driver each effect of the catalogue follows (what its residual is plotted against).
EFFECT_DRIVER: dict[str, str] = {
    "temperature": "temperature",
    "magnetorquer": "torquer_am2",
    "time_offset": "field_rate_nt_s",
    "external_field": "mlat_deg",
    "crustal_field": "mlat_deg",
    "sun_driven": "sun_angle_deg",
    "nonlinearity": "field_nt",
    "orbit_error": "time_h",
    "parameter_drift": "time_h",
    "field_aligned_currents": "mlat_deg",
    "attitude_error": "time_h",
}

#: Number of bins of a curve.
N_BINS = 24


def _sig(x: float, digits: int = 4) -> float | None:
    return None if not math.isfinite(x) else float(f"{x:.{digits}g}")


def _curve(
    driver: Driver,
    x: FloatArray,
    before_nt: FloatArray,
    after_nt: FloatArray,
    holdout: BoolArray,
    t_h: FloatArray,
) -> dict[str, Any] | None:
    ok = np.isfinite(x)
    if np.count_nonzero(ok) < 2 * N_BINS or float(np.ptp(x[ok])) <= 0.0:
        return None
    if driver.quantile_bins:
        edges = np.unique(np.quantile(x[ok], np.linspace(0.0, 1.0, N_BINS + 1)))
    else:
        edges = np.linspace(float(x[ok].min()), float(x[ok].max()), N_BINS + 1)
    if edges.size < 3:
        return None
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    centres, rms_before, rms_after, counts = [], [], [], []
    for b in range(edges.size - 1):
        m = ok & (which == b)
        if not m.any():
            continue
        centres.append(_sig(float(np.mean(x[m]))))
        rms_before.append(_sig(rms_nt(before_nt[m])))
        rms_after.append(_sig(rms_nt(after_nt[m])))
        counts.append(int(np.count_nonzero(m)))
    held_from = None
    if driver.key == "time_h" and holdout.any():
        held_from = _sig(float(t_h[holdout].min()))
    return {
        "driver": driver.key,
        "name": driver.name,
        "label": driver.label,
        "x": centres,
        "rms_before_nt": rms_before,
        "rms_after_nt": rms_after,
        "n": counts,
        "held_out_from": held_from,
    }


def evidence(data: DiagnosisData, att: Attribution) -> list[dict[str, Any]]:
    """Curves of the residual RMS (per component, nT) before and after the selected effects,
    binned by each selected effect's driver, then by magnetic latitude and time.

    Parameters
    ----------
    data : DiagnosisData
    att : Attribution
        ``baseline_residual_nt`` (the 12-parameter calibration alone) is "before",
        ``final_residual_nt`` (with every selected effect) is "after"; all samples, training and
        held-out (``held_out_from`` marks the held-out span on the time curve).

    Returns
    -------
    list of dict
        ``driver``, ``name`` (short), ``label`` (with unit), ``effects`` (the selected effects
        it drives), ``x`` (bin means), ``rms_before_nt``, ``rms_after_nt``, ``n`` (samples per
        bin), ``held_out_from``.
    """
    order: dict[str, list[str]] = {}
    for name in att.selected:
        order.setdefault(EFFECT_DRIVER.get(name, "time_h"), []).append(name)
    for key in ("mlat_deg", "time_h"):
        order.setdefault(key, [])
    t_h = _time_h(data)
    curves = []
    for key, effects in order.items():
        driver = DRIVERS[key]
        x = driver.values(data)
        if x is None:
            continue
        curve = _curve(
            driver,
            np.asarray(x, dtype=float),
            att.baseline_residual_nt,
            att.final_residual_nt,
            att.holdout,
            t_h,
        )
        if curve is not None:
            curves.append({**curve, "effects": effects})
    return curves
