"""Calibration health: is the calibration in service still fitting what the spacecraft sends?

Each batch of new samples gives one point of a series: the RMS of CONTRACT "Definitions"
(:func:`orbitcal.metrics.rms_nt`, over the batch's N × 3 residual ``b_cal − b_ref``) and the
residual's white-noise level (:func:`orbitcal.diagnose.noise.noise_floor_nt`, from second
differences, which slow errors cancel in). One rule decides when the calibration has gone stale
(docs/design.md, "Calibration health"):

**A one-sided CUSUM on the log ratio of the batch RMS to the calibration's own held-out RMS**
(Page 1954). With ``x_k = ln(rms_k / rms_ref)``, where ``rms_ref`` is the document's
``metrics.holdout_rms_nt`` (what the calibration left on data no fit saw),

    S_0 = 0,   S_k = max(0, S_{k-1} + x_k − κ),   stale at the first k with S_k ≥ h,

with ``κ = ln 2`` (an error up to twice the held-out one is tolerated) and ``h = ln 4``. The change
began at the first point after the last ``S_j = 0`` before the alarm (the CUSUM's
maximum-likelihood change point); inside that point and the one before, the sample where it began
is the maximum-likelihood split of a change in variance (:func:`variance_change_index`).

False alarms: an alarm needs ``Σ (x_i − κ) ≥ h`` over a run of m points, i.e. a mean log ratio of
``κ + h/m``. For ``x_k`` independent ``N(0, s²)`` the likeliest run is m = h/κ = 2 and the
per-point false-alarm probability is about ``Φ(−(mκ + h)/(s√m)) = Φ(−1.96/s)``: 2e-15 at
s = 0.25, 4e-5 at s = 0.5 (:func:`false_alarm_rate`; other run lengths add to it: 2e5 simulated
points at s = 0.5 gave 1.05e-4). The RMS of 1,000 white-noise values has s ≈ 0.02.
Detection delay for a sustained ratio ρ > 2: ``⌈h / (ln ρ − κ)⌉`` points (:meth:`ChangeRule.delay`):
one for ρ ≥ 8, two for ρ = 4, four for ρ = 3; a ratio of 2 or less is never flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.stats import norm

from orbitcal.arrays import FloatArray

__all__ = [
    "Alarm",
    "ChangeRule",
    "cusum",
    "false_alarm_rate",
    "first_alarm",
    "variance_change_index",
]


@dataclass(frozen=True)
class ChangeRule:
    """The one-sided CUSUM of the module docstring: drift ``kappa`` and threshold ``h`` [ln]."""

    kappa: float = math.log(2.0)
    h: float = math.log(4.0)

    def step(self, s_prev: float, rms_nt: float, ref_rms_nt: float) -> float:
        """``max(0, s_prev + ln(rms / ref) − κ)``."""
        x = math.log(max(rms_nt, 1e-12) / max(ref_rms_nt, 1e-12))
        return max(0.0, s_prev + x - self.kappa)

    def alarm(self, s: float) -> bool:
        return s >= self.h

    def delay(self, ratio: float) -> int | None:
        """Points from the change to the alarm for a sustained RMS ratio; None: never."""
        gain = math.log(ratio) - self.kappa
        return None if gain <= 0 else max(1, math.ceil(self.h / gain - 1e-12))


@dataclass(frozen=True)
class Alarm:
    """Where a series raised the alarm: the point of the alarm and the first point of its run."""

    at: int
    run_start: int


def cusum(
    rms_nt: npt.ArrayLike, ref_rms_nt: npt.ArrayLike, rule: ChangeRule | None = None
) -> FloatArray:
    """The CUSUM ``S_k`` of a series of batch RMS against reference levels (both [nT], (K,))."""
    rule = rule or ChangeRule()
    r = np.asarray(rms_nt, dtype=float)
    ref = np.broadcast_to(np.asarray(ref_rms_nt, dtype=float), r.shape)
    out = np.empty(r.shape)
    s = 0.0
    for k in range(r.shape[0]):
        s = rule.step(s, float(r[k]), float(ref[k]))
        out[k] = s
    return out


def first_alarm(
    rms_nt: npt.ArrayLike, ref_rms_nt: npt.ArrayLike, rule: ChangeRule | None = None
) -> Alarm | None:
    """The first alarm of the series and the first point of the run that led to it."""
    rule = rule or ChangeRule()
    s = cusum(rms_nt, ref_rms_nt, rule)
    hits = np.flatnonzero(s >= rule.h)
    if hits.size == 0:
        return None
    k = int(hits[0])
    zeros = np.flatnonzero(s[:k] == 0.0)
    return Alarm(at=k, run_start=int(zeros[-1]) + 1 if zeros.size else 0)


def variance_change_index(residual_nt: npt.ArrayLike) -> int:
    """Index of the first sample after a change in the residual's variance (N, 3) [nT].

    The maximum-likelihood split of a zero-mean Gaussian sequence into two variances: the ``j``
    maximising ``−j ln σ̂²(:j) − (N − j) ln σ̂²(j:)`` over ``1 ≤ j < N``, per-sample mean squares
    over the three components. 0 when there are fewer than two samples.
    """
    r = np.asarray(residual_nt, dtype=float)
    r = r.reshape(r.shape[0], -1)
    e = np.mean(r**2, axis=1)
    n = e.shape[0]
    if n < 2:
        return 0
    c = np.cumsum(e)
    j = np.arange(1, n)
    before = np.maximum(c[:-1] / j, 1e-300)
    after = np.maximum((c[-1] - c[:-1]) / (n - j), 1e-300)
    return int(j[np.argmax(-j * np.log(before) - (n - j) * np.log(after))])


def false_alarm_rate(spread: float, rule: ChangeRule | None = None) -> float:
    """Approximate false alarms per point for ``x_k ~ N(0, spread²)`` (module docstring)."""
    rule = rule or ChangeRule()
    m = max(1.0, rule.h / rule.kappa)
    return float(norm.sf((m * rule.kappa + rule.h) / (spread * math.sqrt(m))))
