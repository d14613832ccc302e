"""One confirmation of the chosen model on a final block of time no selection step saw.

The chosen model (fitted on the training span) and the calibration alone (fitted there too) both
forecast the final block (their columns and their noise models' forecast from the training
residual, :func:`~orbitcal.diagnose.model.noise_model.forecast_noise`); their errors are
whitened by the training span's noise model and compared sample by sample with the Clark &
West (2007) adjusted loss difference of nested models,

    d_t = sum_axes [ w_base^2 - (w_model^2 - (w_base - w_model)^2) ],

whose mean is tested one-sided (H1: the model forecasts better) with a Newey & West (1987)
variance (Bartlett kernel, bandwidth by Andrews' (1991) AR(1) plug-in rule on ``d`` itself, so
that it lengthens with what persistence whitening leaves) so that what autocorrelation
whitening leaves does not make the test liberal (Diebold & Mariano 1995). The block's RMS before
and after are the contract's ``holdout_rms_*_nt`` (per component).

The adjusted loss tests whether the model's forecast carries information the calibration's lacks
(forecast encompassing), not whether it is closer: a forecast that moves the right way and
overshoots threefold passes it with a worse RMS. A model is confirmed (:meth:`Confirmation.passes`)
only when the test rejects **and** its forecast is closer: the RMS the report shows is lower. On
the storm pass at nadir a model that took the block from 721 to 1126 nT had p = 1e-26. The
whitened squared error (the plain loss difference's mean, ``gain_whitened``) is reported but does
not decide: whitening under a persistent noise model hardly counts a level error (that nadir model
was "closer" whitened), and beside a large unmodelled field (a 90 nT attitude walk) it called a
torquer that took the block from 94.3 to 91.9 nT farther.

Both errors are whitened once more by the base forecast's predictive covariance
(:func:`predictive_rows`, :class:`BaseUncertainty`): under the base model its forecast error is the
noise's innovations plus one draw of the training span's parameter error along the base model's
columns on the block, which the noise model alone counts as hundreds of independent samples: a
candidate that only bends an ill-pinned calibration's extrapolation (a storm pass's 11 quiet
minutes at nadir, ``docs/design.md``) was confirmed at p below 1e-17.

The shrink (RMS before over after) carries a moving-block bootstrap interval (Kuensch 1989):
blocks of the final block's errors, before and after together, at least an orbit long so that
what persists within an orbit (an unmodelled field along the track) stays within a block, drawn
with replacement to the block's length; the interval is the bootstrap distribution's central
:data:`SHRINK_INTERVAL_LEVEL`. A final block shorter than :data:`SHRINK_MIN_BLOCKS` orbits has
no interval (``None``): a block of one orbit drawn once or twice is one forecast, not a
distribution.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.model.noise_model import AxisNoise

__all__ = [
    "SHRINK_BOOTSTRAP_DRAWS",
    "SHRINK_INTERVAL_LEVEL",
    "SHRINK_MIN_BLOCKS",
    "BaseUncertainty",
    "Confirmation",
    "andrews_bandwidth",
    "clark_west",
    "confirm",
    "newey_west_variance",
    "predictive_rows",
    "shrink_interval",
    "whitened_rows",
]

#: Central probability of the shrink's bootstrap interval.
SHRINK_INTERVAL_LEVEL = 0.9
#: Bootstrap draws of the shrink's interval (its ends move by ~1 % of the interval's width
#: between seeds at this many).
SHRINK_BOOTSTRAP_DRAWS = 1000
#: The least length of the final block, in bootstrap blocks (orbits), for a shrink interval.
SHRINK_MIN_BLOCKS = 2


@dataclass(frozen=True)
class Confirmation:
    """The chosen model against the calibration alone on the final block.

    Attributes
    ----------
    holdout_rms_before_nt, holdout_rms_after_nt : float
        RMS over samples and components of the calibration's and the model's errors [nT].
    p_value : float
        One-sided p-value of the model forecasting better (1.0 for the calibration alone).
    statistic : float
        The test's z statistic.
    n_samples : int
        Samples of the final block.
    gain_whitened : float
        Mean over the block's samples of the whitened squared error of the calibration minus
        the model's (summed over axes; positive: the model forecasts closer).
    shrink_interval : tuple of float, optional
        The moving-block bootstrap interval of :attr:`shrink` (:func:`shrink_interval`); None
        when the block is too short for one.
    bootstrap_block_samples : int
        The bootstrap's block length in samples (0: no interval).
    """

    holdout_rms_before_nt: float
    holdout_rms_after_nt: float
    p_value: float
    statistic: float
    n_samples: int
    gain_whitened: float = 0.0
    shrink_interval: tuple[float, float] | None = None
    bootstrap_block_samples: int = 0

    @property
    def shrink(self) -> float:
        """RMS before over after (the contract's ``shrink``; infinite for a perfect forecast)."""
        after = self.holdout_rms_after_nt
        return self.holdout_rms_before_nt / after if after > 0.0 else math.inf

    def passes(self, level: float) -> bool:
        """Whether the model forecasts the block better: the test rejects at ``level`` and the
        model is closer (:meth:`closer`)."""
        return self.rejects(level) and self.closer()

    def closer(self) -> bool:
        """Whether the model's forecast is closer: a lower RMS on the block."""
        return self.holdout_rms_after_nt < self.holdout_rms_before_nt

    def rejects(self, level: float) -> bool:
        """Whether the test alone rejects at ``level``."""
        return self.p_value <= level

    def to_json(self) -> dict[str, float | int | list[float] | None]:
        """The contract's ``confirmation`` with the test's statistic and sample count, and the
        shrink with its bootstrap interval."""
        interval = self.shrink_interval
        return {
            "holdout_rms_before_nt": round(self.holdout_rms_before_nt, 4),
            "holdout_rms_after_nt": round(self.holdout_rms_after_nt, 4),
            "p_value": float(f"{self.p_value:.4g}"),
            "statistic": round(self.statistic, 4),
            "n_samples": self.n_samples,
            "gain_whitened": float(f"{self.gain_whitened:.4g}"),
            "shrink": _finite_or_none(self.shrink),
            "shrink_interval_90": None if interval is None else [round(v, 4) for v in interval],
            "bootstrap_block_samples": self.bootstrap_block_samples,
        }


def _finite_or_none(x: float) -> float | None:
    return round(x, 4) if math.isfinite(x) else None


def shrink_interval(
    e_base_nt: FloatArray,
    e_model_nt: FloatArray,
    block_samples: int,
    *,
    draws: int = SHRINK_BOOTSTRAP_DRAWS,
    level: float = SHRINK_INTERVAL_LEVEL,
) -> tuple[float, float] | None:
    """The moving-block bootstrap interval of the shrink ``rms(e_base) / rms(e_model)`` over the
    rows of the final block's errors (m, 3), blocks of ``block_samples`` rows; None when the
    block holds fewer than :data:`SHRINK_MIN_BLOCKS` of them. Seeded by the block's size, so a
    report is reproducible."""
    m = int(e_base_nt.shape[0])
    length = max(int(block_samples), 1)
    if m < SHRINK_MIN_BLOCKS * length:
        return None
    base = np.sum(np.asarray(e_base_nt, dtype=float) ** 2, axis=1)
    model = np.sum(np.asarray(e_model_nt, dtype=float) ** 2, axis=1)
    # sums over every block of ``length`` consecutive rows (the moving blocks)
    sum_base, sum_model = _moving_sums(base, length), _moving_sums(model, length)
    k = -(-m // length)  # blocks per draw: a series at least as long as the block
    rng = np.random.default_rng([m, length])
    starts = rng.integers(0, sum_base.size, size=(draws, k))
    num, den = sum_base[starts].sum(axis=1), sum_model[starts].sum(axis=1)
    ratio = np.sqrt(num / np.maximum(den, np.finfo(float).tiny))
    tail = 50.0 * (1.0 - level)
    lo, hi = np.percentile(ratio, [tail, 100.0 - tail])
    return float(lo), float(hi)


def _moving_sums(x: FloatArray, length: int) -> FloatArray:
    """The sums of every ``length`` consecutive values of ``x`` (one cumulative sum: linear in
    the rows, where a convolution costs rows times ``length``)."""
    c = np.concatenate(([0.0], np.cumsum(x)))
    return np.asarray(c[length:] - c[:-length])


def andrews_bandwidth(d: FloatArray) -> int:
    """Andrews' (1991) bandwidth of the Bartlett kernel for the series ``d``, its AR(1)
    plug-in: ``1.1447 (alpha T)^(1/3)``, ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``."""
    d = np.asarray(d, dtype=float) - float(np.mean(d))
    t = d.size
    den = float(d[:-1] @ d[:-1])
    rho = float(d[1:] @ d[:-1]) / den if den > 0.0 else 0.0
    rho = min(max(rho, -ANDREWS_MAX_RHO), ANDREWS_MAX_RHO)
    alpha = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return int(min(1.1447 * (alpha * t) ** (1.0 / 3.0), t - 1))


#: The AR(1) coefficient of :func:`andrews_bandwidth` is clipped to this (Andrews 1991 sec. 6).
ANDREWS_MAX_RHO = 0.97


def newey_west_variance(d: FloatArray, bandwidth: int | None = None) -> float:
    """Long-run variance of the series ``d`` (Bartlett weights); bandwidth by Andrews' rule."""
    d = np.asarray(d, dtype=float) - float(np.mean(d))
    t = d.size
    lags = andrews_bandwidth(d) if bandwidth is None else bandwidth
    var = float(d @ d) / t
    for k in range(1, min(lags, t - 1) + 1):
        var += 2.0 * (1.0 - k / (lags + 1.0)) * float(d[k:] @ d[:-k]) / t
    return max(var, 0.0)


def whitened_rows(e: FloatArray, noise: Sequence[AxisNoise], run_start: np.ndarray) -> FloatArray:
    """``e`` (m, 3) or (m, 3, s) whitened per axis by ``noise``, the rows whose whitening is
    complete."""
    out = np.zeros_like(e)
    valid = np.ones(e.shape[0], dtype=bool)
    for i, nz in enumerate(noise):
        out[:, i], ok = nz.whiten(e[:, i], run_start)
        valid &= ok
    return out[valid]


@dataclass(frozen=True)
class BaseUncertainty:
    """What the base forecast's own parameters leave uncertain on the final block: their
    columns there and their posterior covariance from the training span.

    Attributes
    ----------
    whitened : ndarray, shape (k, 3, p)
        The base model's columns (the calibration's 12, then its effects') on the final block,
        in the units of the parameters' covariance (the forecast is ``columns @ params``),
        whitened by the test's noise model as :func:`confirm` whitens the errors
        (:func:`whitened_rows` with the same noise model and run starts: the same rows).
    cov : ndarray, shape (p, p)
        The parameters' posterior covariance on the training span, under the noise model the
        test whitens with.
    """

    whitened: FloatArray
    cov: FloatArray


def predictive_rows(w: FloatArray, z: FloatArray, cov: FloatArray) -> FloatArray:
    """Whitened errors ``w`` (k, 3) whitened once more by the base forecast's predictive
    covariance ``I + Z cov Z'`` (``z`` (k, 3, p) its whitened columns): ``(I + Z cov Z')^(-1/2) w``.

    Under the base model the whitened forecast error is the noise's innovations **plus** the
    error of the parameters estimated on the training span, ``Z (beta_hat - beta)``: one draw
    for the whole block, along the directions the base model's columns take there. On a span
    where the data hardly pin the calibration (a storm pass's 11 quiet minutes at nadir, whose
    matrix elements the training span leaves at 90-1100 nT of posterior deviation) that error
    is the forecast's largest part, and any candidate that bends the extrapolation forecast a
    block of 360 samples "better" at p 1e-34. Whitened by the full predictive covariance, the
    base error is again unit white noise under the base model, and an improvement along what
    the base model's own uncertainty allows counts for what it is: one draw. Where the training
    span pins the parameters (``Z' Z cov`` small: a day, a week) the rows hardly change."""
    k = w.shape[0]
    if k == 0 or cov.size == 0:
        return w
    zf = z.reshape(3 * k, -1)
    vals, vecs = np.linalg.eigh(zf.T @ zf)  # Z = U S W': W = vecs, S^2 = vals
    keep = vals > vals.max(initial=0.0) * 1e-12
    if not np.any(keep):
        return w
    s, wv = np.sqrt(vals[keep]), vecs[:, keep]
    lam, v = np.linalg.eigh((s[:, None] * (wv.T @ cov @ wv)) * s[None, :])
    shrink = 1.0 / np.sqrt(1.0 + np.maximum(lam, 0.0)) - 1.0
    # U = Z W S^-1; (I + U M U')^(-1/2) = I + U V diag(shrink) V' U'
    a = (wv / s[None, :]) @ v
    out = w.reshape(-1) + zf @ (a @ (shrink * (a.T @ (zf.T @ w.reshape(-1)))))
    return out.reshape(k, 3)


def confirm(
    e_base_nt: FloatArray,
    e_model_nt: FloatArray,
    noise: Sequence[AxisNoise],
    run_start: np.ndarray,
    block_samples: int = 0,
    base: BaseUncertainty | None = None,
) -> Confirmation:
    """The confirmation from the forecast errors of the calibration alone and of the chosen
    model on the final block, (m, 3) each [nT] (identical arrays: the model is the calibration);
    with ``block_samples`` (an orbit's samples), the shrink's bootstrap interval; with ``base``,
    the errors whitened by the base forecast's predictive covariance (:func:`predictive_rows`)."""
    before = float(np.sqrt(np.mean(e_base_nt**2)))
    after = float(np.sqrt(np.mean(e_model_nt**2)))
    n = int(e_base_nt.shape[0])
    if np.array_equal(e_base_nt, e_model_nt):
        return Confirmation(before, after, 1.0, 0.0, n)
    interval = shrink_interval(e_base_nt, e_model_nt, block_samples) if block_samples else None
    blocks = block_samples if interval is not None else 0
    wb = whitened_rows(e_base_nt, noise, run_start)
    wm = whitened_rows(e_model_nt, noise, run_start)
    if base is not None:
        wb, wm = (
            predictive_rows(wb, base.whitened, base.cov),
            predictive_rows(wm, base.whitened, base.cov),
        )
    z, p, gain = clark_west(wb, wm)
    return Confirmation(before, after, p, z, n, gain, interval, blocks)


def clark_west(w_base: FloatArray, w_model: FloatArray) -> tuple[float, float, float]:
    """The test of :func:`confirm` on whitened errors (k, 3): its z statistic (1e9 for a
    perfect forecast), one-sided p-value and ``gain_whitened``."""
    wb, wm = w_base, w_model
    d = np.sum(wb**2 - (wm**2 - (wb - wm) ** 2), axis=1)
    gain = float(np.mean(np.sum(wb**2 - wm**2, axis=1))) if d.size else 0.0
    if d.size < 3:
        return 0.0, 1.0, gain
    var = newey_west_variance(d)
    se = math.sqrt(var / d.size) if var > 0.0 else 0.0
    mean = float(np.mean(d))
    z = mean / se if se > 0.0 else (math.inf if mean > 0.0 else 0.0)
    p = 0.5 * math.erfc(z / math.sqrt(2.0)) if math.isfinite(z) else 0.0
    return (float(z) if math.isfinite(z) else 1e9), float(p), gain
