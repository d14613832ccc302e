"""A per-axis noise model of a residual: white noise plus an autoregressive part or a random-walk
offset, its order chosen by the Bayesian information criterion (Schwarz 1978).

The candidates for one axis's residual ``r_t`` (samples in contiguous runs) are

* ``AR(p)``, ``p = 0 .. max_order``: ``r_t = sum_k phi_k r_(t-k) + e_t``;
* ``I(1)+AR(q)``, ``q = 0 .. max_order - 1``: the same on ``r_t - r_(t-1)``;
* a local level (white noise plus a random-walk offset, ARIMA(0, 1, 1)): the differences an MA(1)
  of coefficient ``theta`` on a grid (:data:`LEVEL_THETAS`), whitened by ``(1 - L) / (1 + theta L)``
  truncated after :data:`LEVEL_TAPS` taps,
* long memory (a 1/f-like spectrum): ``(1 - L)^d r_t`` an AR(1), ``d`` on a grid
  (:data:`FRAC_DS`), the fractional difference truncated to the local level's history,

each fitted by conditional least squares on the same samples (every run's first
:func:`noise_skip` dropped, so that the likelihoods compare) and scored by
``n log(s^2) + (k + 1) log n``. The chosen model's filter ``a(L) = 1 - sum phi_k L^k`` (times
``1 - L`` for a random walk) maps the residual to its innovations, of standard deviation
``sigma``: every comparison of the model core is made on ``a(L) x / sigma``
(:meth:`AxisNoise.whiten`), for the data and every column alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import lfilter, lfiltic

from orbitcal.arrays import FloatArray

if TYPE_CHECKING:
    from orbitcal.diagnose.data import DiagnosisData

__all__ = [
    "AxisNoise",
    "fit_axis_noise",
    "fit_noise",
    "forecast_noise",
    "noise_skip",
    "run_starts",
    "runs_of_index",
]

IntArray = np.ndarray


@dataclass(frozen=True)
class AxisNoise:
    """One axis's noise model.

    Attributes
    ----------
    kind : {"ar", "rw", "level", "frac"}
        Autoregressive, a random-walk offset (differences autoregressive), a local level, or
        long memory (fractional differences autoregressive).
    phi : ndarray, shape (p,)
        Autoregressive coefficients (of the differences for ``"rw"``); ``[theta]`` for
        ``"level"``; ``[d, phi_1]`` for ``"frac"``.
    sigma_nt : float
        Standard deviation of the innovations [nT].
    bic : float
        The criterion of the chosen model.
    """

    kind: str
    phi: FloatArray
    sigma_nt: float
    bic: float

    @property
    def filter(self) -> FloatArray:
        """The whitening filter's coefficients ``a_0 = 1, a_1, ...`` (``e_t = sum a_j r_(t-j)``)."""
        if self.kind == "level":
            return level_filter(float(self.phi[0]))
        if self.kind == "frac":
            return np.convolve(frac_filter(float(self.phi[0])), [1.0, -float(self.phi[1])])
        a = np.r_[1.0, -np.asarray(self.phi, dtype=float)]
        return np.convolve(a, [1.0, -1.0]) if self.kind == "rw" else a

    @property
    def lag(self) -> int:
        """Samples of history a whitened value needs."""
        return int(self.filter.size - 1)

    def describe(self) -> str:
        """E.g. ``"AR(2), sigma 2.01 nT"`` or ``"random-walk offset + AR(1), sigma ..."``."""
        if self.kind == "level":
            return (
                f"white noise + random-walk offset (ARIMA(0,1,1), theta {float(self.phi[0]):.3f}), "
                f"innovations sigma {self.sigma_nt:.4g} nT"
            )
        if self.kind == "frac":
            return (
                f"long memory (fractional difference d {float(self.phi[0]):.2f}) + AR(1) "
                f"{float(self.phi[1]):.3f}, innovations sigma {self.sigma_nt:.4g} nT"
            )
        head = "random-walk offset + " if self.kind == "rw" else ""
        return f"{head}AR({self.phi.size}), innovations sigma {self.sigma_nt:.4g} nT"

    def whiten(self, x: FloatArray, run_start: IntArray) -> tuple[FloatArray, np.ndarray]:
        """``a(L) x / sigma`` along the first axis, and which rows are valid (whole history
        inside their run). ``run_start[t]`` is the position of the first sample of ``t``'s run.
        Invalid rows are set to zero."""
        return whiten_with(self.filter, self.sigma_nt, x, run_start)


#: Taps of the truncated inverse of ``1 + theta L`` in the local-level model's filter: the
#: largest ``|theta|`` tried (:data:`LEVEL_THETAS`) decays to 1 % within them.
LEVEL_TAPS = 48
#: The moving-average coefficients tried for white noise plus a random-walk offset (the
#: differences are MA(1) with ``theta = -(1 - signal share)``, Harvey 1989, sec. 2.3).
LEVEL_THETAS = tuple(-x for x in (0.2, 0.4, 0.6, 0.7, 0.8, 0.85, 0.9))


def level_filter(theta: float) -> FloatArray:
    """``(1 - L) / (1 + theta L)``, the inverse truncated after :data:`LEVEL_TAPS` taps."""
    inv = (-theta) ** np.arange(LEVEL_TAPS)
    return np.convolve([1.0, -1.0], inv)


#: The fractional differences ``d`` tried for long-memory noise (``d = 0.5``: a 1/f spectrum;
#: Granger & Joyeux 1980, Hosking 1981), each with an AR(1) on top.
FRAC_DS = (0.1, 0.2, 0.3, 0.4, 0.5)


def frac_filter(d: float) -> FloatArray:
    """``(1 - L)^d`` truncated after ``LEVEL_TAPS - 1`` taps (with the AR(1) on top, the filter's
    history is the local level's, so every noise model is scored on the same samples)."""
    k = np.arange(1, LEVEL_TAPS - 1)
    return np.r_[1.0, np.cumprod((k - 1.0 - d) / k)]


def filtered(a: FloatArray, x: FloatArray) -> FloatArray:
    """``sum_j a_j x[t - j]`` along the first axis, ``x`` taken as zero before its first row."""
    out = a[0] * np.asarray(x, dtype=float)
    for j in range(1, a.size):
        out[j:] += a[j] * x[:-j]
    return out


def whiten_with(
    a: FloatArray, sigma: float, x: FloatArray, run_start: IntArray
) -> tuple[FloatArray, np.ndarray]:
    """``sum_j a_j x[t - j] / sigma`` (rows whose history leaves their run are zero and invalid)."""
    x = np.asarray(x, dtype=float)
    t = np.arange(x.shape[0])
    valid = (t - np.asarray(run_start)) >= a.size - 1
    out = filtered(a, x)
    out[~valid] = 0.0
    out /= sigma
    return out, valid


def runs_of_index(index: IntArray, step: int = 1) -> IntArray:
    """For positions ``0 .. len(index) - 1`` of sample numbers ``index``, the position where each
    one's run begins (a run: consecutive entries ``step`` apart)."""
    index = np.asarray(index)
    if index.size == 0:
        return np.zeros(0, dtype=np.intp)
    new = np.r_[True, np.diff(index) != step]
    starts = np.flatnonzero(new)
    return np.asarray(starts[np.cumsum(new) - 1], dtype=np.intp)


def _lags(
    r: FloatArray, run_start: IntArray, order: int, skip: int
) -> tuple[FloatArray, FloatArray]:
    """Targets ``r_t`` and lag matrix ``[r_(t-1) .. r_(t-order)]`` on rows with ``skip`` samples of
    history inside their run."""
    t = np.arange(r.size)
    rows = t[(t - run_start) >= skip]
    lagged = np.column_stack([r[rows - k] for k in range(1, order + 1)]) if order else None
    return r[rows], (lagged if lagged is not None else np.zeros((rows.size, 0)))


def _candidate(
    r: FloatArray, run_start: IntArray, order: int, skip: int
) -> tuple[FloatArray, float, int]:
    """Least-squares AR(order) coefficients, innovation variance and sample count."""
    y, x = _lags(r, run_start, order, skip)
    if y.size <= order + 2:
        return np.zeros(order), float(np.var(y)) if y.size else 1.0, int(y.size)
    phi = np.linalg.lstsq(x, y, rcond=None)[0] if order else np.zeros(0)
    e = y - x @ phi
    return np.asarray(phi), float(np.mean(e**2)), int(y.size)


def fit_axis_noise(r_nt: FloatArray, run_start: IntArray, *, max_order: int) -> AxisNoise:
    """The noise model of one axis's residual ``r_nt`` (runs given by ``run_start``,
    :func:`runs_of_index`): the candidate of least BIC (see the module)."""
    r = np.asarray(r_nt, dtype=float) - float(np.mean(r_nt))
    skip = noise_skip(max_order)
    d = np.r_[0.0, np.diff(r)]
    best = _best_level(r, run_start, skip)
    frac = _best_frac(r, run_start, skip)
    if frac is not None and (best is None or frac.bic < best.bic):
        best = frac
    for kind, series, orders in (
        ("ar", r, range(max_order + 1)),
        ("rw", d, range(max_order)),
    ):
        for p in orders:
            phi, var, n = _candidate(series, run_start, p, skip)
            if n < 4 or var <= 0.0:
                continue
            bic = n * float(np.log(var)) + (p + 1) * float(np.log(n))
            if best is None or bic < best.bic:
                best = AxisNoise(kind, phi, float(np.sqrt(var)), bic)
    if best is None:  # too few samples: white with the sample variance
        best = AxisNoise("ar", np.zeros(0), float(np.std(r)) or 1.0, float("nan"))
    return best


def noise_skip(max_order: int) -> int:
    """Samples at the start of each run every noise model's likelihood leaves out (the longest
    filter's history), so that all are of the same samples."""
    return max(max_order, LEVEL_TAPS) + 1


def _best_level(r: FloatArray, run_start: IntArray, skip: int) -> AxisNoise | None:
    """The local-level model (white noise + a random-walk offset) of least BIC over
    :data:`LEVEL_THETAS` (one parameter and the variance)."""
    best: AxisNoise | None = None
    t = np.arange(r.size)
    rows = (t - run_start) >= skip
    n = int(rows.sum())
    if n < 4:
        return None
    for theta in LEVEL_THETAS:
        e, _ = whiten_with(level_filter(theta), 1.0, r, run_start)
        var = float(np.mean(e[rows] ** 2))
        if var <= 0.0:
            continue
        bic = n * float(np.log(var)) + 2 * float(np.log(n))
        if best is None or bic < best.bic:
            best = AxisNoise("level", np.array([theta]), float(np.sqrt(var)), bic)
    return best


def _best_frac(r: FloatArray, run_start: IntArray, skip: int) -> AxisNoise | None:
    """The long-memory model (``(1 - L)^d`` then an AR(1)) of least BIC over :data:`FRAC_DS`
    (three parameters and the variance)."""
    best: AxisNoise | None = None
    for d in FRAC_DS:
        e, _ = whiten_with(frac_filter(d), 1.0, r, run_start)
        phi, var, n = _candidate(e, run_start, 1, skip)
        if n < 4 or var <= 0.0:
            continue
        bic = n * float(np.log(var)) + 3 * float(np.log(n))
        if best is None or bic < best.bic:
            best = AxisNoise("frac", np.array([d, float(phi[0])]), float(np.sqrt(var)), bic)
    return best


def fit_noise(
    residual_nt: FloatArray, run_start: IntArray, *, max_order: int
) -> tuple[AxisNoise, ...]:
    """One :class:`AxisNoise` per column of ``residual_nt`` (m, 3)."""
    return tuple(
        fit_axis_noise(residual_nt[:, i], run_start, max_order=max_order)
        for i in range(residual_nt.shape[1])
    )


def describe_noise(noise: Sequence[AxisNoise]) -> list[str]:
    """One line per axis."""
    return [f"{axis}: {n.describe()}" for axis, n in zip("xyz", noise, strict=False)]


def run_starts(data: DiagnosisData, index: IntArray, step: int) -> IntArray:
    """Per position of ``index``, where its run begins: consecutive samples ``step`` apart, no
    time gap over three median steps."""
    index = np.asarray(index)
    if index.size == 0:
        return np.zeros(0, dtype=np.intp)
    t = data.t_utc_s[index]
    dt = np.diff(t)
    gap = dt > 3.0 * float(np.median(dt)) if dt.size else np.zeros(0, dtype=bool)
    new = np.r_[True, (np.diff(index) != step) | gap]
    starts = np.flatnonzero(new)
    return np.asarray(starts[np.cumsum(new) - 1], dtype=np.intp)


def forecast_noise(
    noise: Sequence[AxisNoise],
    residual_nt: FloatArray,
    index: IntArray,
    step: int,
    targets: IntArray,
) -> FloatArray:
    """The noise models' forecast of the residual at the sample numbers ``targets`` (k, 3) [nT],
    given the training residual ``residual_nt`` (m, 3) at the sample numbers ``index`` (a grid
    ``step`` apart, the noise models' cadence), from the end of its last run.

    A model with noise forecasts the noise as well as its columns (regression with ARIMA errors,
    Box & Jenkins 1976, ch. 9): with innovations set to zero beyond the training span, the filter
    ``a(L)`` gives ``r_t = -sum_(j>=1) a_j r_(t-j)``, started from the last run's deviations from
    its mean (the mean added back: a unit root keeps a level whatever it is, a stationary part
    decays to it). Under a random-walk offset the forecast is the level the training span ended
    at, the level the model's calibration offsets cannot pin (the offsets' columns whitened by a
    difference are zero); under white noise it is the residual's mean. A target is read at the
    nearest grid position after the training span's last sample."""
    index = np.asarray(index)
    targets = np.asarray(targets)
    out = np.zeros((targets.size, residual_nt.shape[1]))
    if index.size == 0 or targets.size == 0:
        return out
    last = int(index[-1])
    ahead = np.maximum(np.rint((targets - last) / max(step, 1)).astype(np.intp), 1)
    horizon = int(ahead.max())
    run_begin = int(runs_of_index(index, step)[-1])
    for i, nz in enumerate(noise):
        a = nz.filter
        lag = a.size - 1
        r = np.asarray(residual_nt[:, i], dtype=float)
        mean = float(np.mean(r))
        hist = r[max(run_begin, index.size - lag) :] - mean
        past = np.zeros(lag)
        past[lag - hist.size :] = hist
        if lag:  # the all-pole filter 1 / a(L) run on zero innovations from the past's state
            state = lfiltic([1.0], a, past[::-1])
            path = lfilter([1.0], a, np.zeros(horizon), zi=state)[0]
        else:
            path = np.zeros(horizon)
        out[:, i] = mean + path[ahead - 1]
    return out
