"""Imperfect-model columns: what an effect's own forms leave out when it is real but not exactly
as the catalogue writes it (issue 43, item 2).

The model core (:mod:`orbitcal.diagnose.model`) appends these columns to every form of their
effect, under the shrinkage prior of their ``param_ranges`` (:attr:`Effect.imperfect`). Without
them, the part of a real effect its template misses -- a thermistor that lags the sensor, a coil
whose field lags its command, a clock that drifts, a storm deeper on the dusk side, cross-axis
terms of a sensor's transfer function -- is left to whichever other group's columns take most of
it, and with tens of thousands of samples that group's inclusion probability goes to one: a
spurious effect beside a right one. Each function here is the first-order physics of one such
departure, general to the effect, not the shape of any one simulator:

* the external field: a ring current's local-time asymmetry (the partial ring current: the axial
  field times the cosine and sine of magnetic local time) and a field across the dipole axis (the
  degree-1 external terms q11, s11 in SM: tail and magnetopause currents);
* the temperature: a lag between the thermistor and the sensor (the temperature through a lag of
  :data:`THERMAL_LAG_REFERENCE_S`, less the temperature, on each axis: a lag ``tau`` adds about
  ``tau / THERMAL_LAG_REFERENCE_S`` times the offset coefficient of this) and a quadratic
  temperature coefficient;
* the magnetorquer: a first-order lag of the coils' field behind their commands (the commands
  through a lag of :data:`TORQUER_LAG_REFERENCE_S`, less the commands: a small lag ``tau`` adds
  about ``tau / TORQUER_LAG_REFERENCE_S`` times this to the field);
* the time offset: a clock that drifts (the field's rate of change times time);
* the nonlinearity: cross-axis quadratic terms (``b_x b_y`` ...), beside the per-axis polynomial.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.columns import Index, PerAxisColumns, ScaledVectorColumns
from orbitcal.diagnose.data import FIELD_SCALE_NT, DiagnosisData, contiguous_runs
from orbitcal.diagnose.design import DesignBlock, _tau_days, _varies

__all__ = [
    "THERMAL_LAG_REFERENCE_S",
    "TORQUER_LAG_REFERENCE_S",
    "clock_drift",
    "cross_nonlinearity",
    "external_asymmetry",
    "temperature_lag",
    "torquer_lag",
]

#: Time constant of the reference lag of the torquer's lag columns [s].
TORQUER_LAG_REFERENCE_S = 10.0
#: Time constant of the reference lag of the temperature's lag columns [s].
THERMAL_LAG_REFERENCE_S = 300.0


def external_asymmetry(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """The axial field times cos and sin of magnetic local time, and the field along SM x and y
    (None without the Sun's direction)."""
    mlt = data.mlt_angle_rad
    sm = data.sm_equatorial_body
    if mlt is None or sm is None:
        return None
    axis = data.dipole_axis_body
    return DesignBlock(
        ScaledVectorColumns(
            data.n, [axis, axis, sm[:, 0], sm[:, 1]], [np.cos(mlt), np.sin(mlt), None, None]
        ),
        [
            "asymmetric_cos_mlt_nt",
            "asymmetric_sin_mlt_nt",
            "across_dipole_sm_x_nt",
            "across_dipole_sm_y_nt",
        ],
        variant="imperfect",
    )


def temperature_lag(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """Per axis, the temperature (about the training mean) through the reference lag less
    itself, and its square."""
    temp = data.hk("temperature")
    if temp is None or not _varies(temp):
        return None
    dtemp = temp - float(np.mean(temp[train]))
    lag = _lagged(data.t_utc_s, dtemp, THERMAL_LAG_REFERENCE_S) - dtemp
    return DesignBlock(
        PerAxisColumns(data.n, [lag, dtemp**2]),
        [f"thermal_lag_{a}_nt_per_degc" for a in "xyz"]
        + [f"thermal_quadratic_{a}_nt_per_degc2" for a in "xyz"],
        variant="imperfect",
    )


def _lagged(t_s: FloatArray, u: FloatArray, tau_s: float) -> FloatArray:
    """``u`` through a first-order lag of time constant ``tau_s`` (held between samples; each
    contiguous run from rest at its first value)."""
    out = np.empty_like(u)
    for run in contiguous_runs(t_s):
        x = u[run]
        if x.size < 2:
            out[run] = x
            continue
        a = float(np.exp(-float(np.median(np.diff(t_s[run]))) / tau_s))
        out[run] = _first_order(x, a)
    return out


def _first_order(x: FloatArray, a: float) -> FloatArray:
    """``y[0] = x[0]``, ``y[k] = a y[k-1] + (1 - a) x[k-1]``: the exact response of a lag to an
    input held between samples, at rest at the first value. A loop over floats (~50 ms at
    86,400 samples) in place of ``scipy.signal.lfilter``; the whole diagnosis was no faster for
    it (``benchmarks/results/diagnose_timing.md``), the rest of scipy being imported anyway."""
    b = 1.0 - a
    y = float(x[0])
    ys = [y]
    for v in x[:-1].tolist():
        y = a * y + b * v
        ys.append(y)
    return np.asarray(ys)


def torquer_lag(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """The commanded dipoles through the reference lag, less the commands, coupled 3 x 3."""
    cols = [data.hk(f"mtq_{a}") for a in "xyz"]
    if all(c is None or not _varies(c) for c in cols):
        return None
    kinds = [
        _lagged(data.t_utc_s, c, TORQUER_LAG_REFERENCE_S) - c if c is not None else np.zeros(data.n)
        for c in cols
    ]
    return DesignBlock(
        PerAxisColumns(data.n, kinds, axis_major=True),
        [f"lag_coupling_{i}{j}_nt_per_am2" for i in "xyz" for j in "xyz"],
        variant="imperfect",
    )


def clock_drift(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """The reference field's rate of change times time (a time-tag error growing linearly)."""
    return DesignBlock(
        ScaledVectorColumns(data.n, [data.db_ref_body_dt_nt_s], [_tau_days(data, train)]),
        ["dt_rate_s_per_day"],
        variant="imperfect",
    )


#: The field components multiplied by each cross-axis term (``b_x b_y, b_y b_z, b_x b_z``).
_PAIRS = ((0, 1), (1, 2), (0, 2))


def _product(b_nt: FloatArray, i: int, j: int, index: Index) -> FloatArray:
    """``b_i b_j / FIELD_SCALE_NT**2`` of the samples ``index``."""
    b = b_nt[index]
    return np.asarray(b[:, i] * b[:, j] / FIELD_SCALE_NT**2)


def cross_nonlinearity(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """Per axis, the three cross products of the field's components."""
    b = data.b_ref_body_nt
    return DesignBlock(
        PerAxisColumns(data.n, [partial(_product, b, i, j) for i, j in _PAIRS], axis_major=True),
        [f"cross_{pair}_{a}_nt" for a in "xyz" for pair in ("xy", "yz", "xz")],
        variant="imperfect",
    )
