"""Blocked cross-validation of the chosen model on the training span (issue 43, item 4).

The posterior (:mod:`orbitcal.diagnose.model.evidence`) is exact for the catalogue's shapes; a
field the catalogue does not write exactly leaves structure that the columns of another effect
can take in sample, with evidence that grows with the number of samples. What such an effect
takes does not, as a rule, *predict*: fitted on the other orbits, it does not shrink the
residual of the orbit left out. So each effect of the chosen model is kept only if the model
with it predicts the left-out orbits of the training span better than the model without it:

* folds: consecutive blocks of one orbital period of training time (a shorter last block joins
  the one before); with fewer than two folds the span cannot be cross-validated and the
  posterior's choice stands;
* for each fold ``k`` every model's parameters are the posterior mean from the whitened Gram
  matrix of the other folds (the same priors as the selection), and its score is the whitened
  squared error on fold ``k`` (``q_k - 2 theta' b_k + theta' G_k theta``): only sums of the fold
  Gram matrices, no rows are kept;
* backward elimination: while some effect's summed gain (score without it minus score with it,
  over the folds) is not positive, the effect of least gain leaves the model.

No level is involved (a gain is positive or not), and the final block is not read: the
confirmation (:mod:`orbitcal.diagnose.model.confirm`) stays untouched.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.model.evidence import Augmented, augment, model_evidence
from orbitcal.diagnose.model.gram import Form, Gram, whitened_grams
from orbitcal.diagnose.model.noise_model import AxisNoise, run_starts
from orbitcal.diagnose.orbit_phase import orbital_period_s

__all__ = ["CrossValidation", "cross_validated", "orbit_folds", "orbital_period_s"]

IntArray = np.ndarray


@dataclass(frozen=True)
class CrossValidation:
    """The cross-validation of the chosen model.

    Attributes
    ----------
    folds : int
        Orbit-long folds of the training span (0: too short, nothing was checked).
    gain : dict of str to float
        Per effect of the posterior's choice, the summed whitened score without it minus with
        it (in the model as it stood when it was decided; positive: it predicts).
    kept : tuple of str
        The effects that stayed, in the posterior's order.
    withdrawn : tuple of str
        The effects that left, in the order they left.
    """

    folds: int
    gain: dict[str, float] = field(default_factory=dict)
    kept: tuple[str, ...] = ()
    withdrawn: tuple[str, ...] = ()

    def to_json(self) -> dict[str, object]:
        return {
            "folds": self.folds,
            "gain_whitened": {e: round(float(g), 3) for e, g in self.gain.items()},
            "kept": list(self.kept),
            "withdrawn": list(self.withdrawn),
        }


def orbit_folds(t_s: FloatArray, period_s: float) -> IntArray:
    """Fold label per sample: orbit-long blocks of time, a last block under half an orbit's
    samples joined to the one before."""
    if t_s.size == 0 or not np.isfinite(period_s) or period_s <= 0.0:
        return np.zeros(t_s.size, dtype=np.intp)
    fold = np.floor((t_s - t_s[0]) / period_s).astype(np.intp)
    last = int(fold.max())
    if last >= 1 and np.sum(fold == last) < 0.5 * np.sum(fold == 0):
        fold[fold == last] = last - 1
    return fold


def _minus(a: Gram, b: Gram) -> Gram:
    return Gram(
        a.cc - b.cc, a.ce - b.ce, a.cy - b.cy, a.ee - b.ee, a.ey - b.ey, a.yy - b.yy, 0, 0.0
    )


def _plus(a: Gram, b: Gram) -> Gram:
    return Gram(
        a.cc + b.cc, a.ce + b.ce, a.cy + b.cy, a.ee + b.ee, a.ey + b.ey, a.yy + b.yy, 0, 0.0
    )


@dataclass(frozen=True)
class _Folds:
    """Each fold's Gram matrix with the calibration's prior, and the rest's."""

    held: list[Augmented]
    rest: list[Augmented]


def _fold_grams(
    data: DiagnosisData,
    index: IntArray,
    fold: IntArray,
    step: int,
    forms: Sequence[Form],
    noise: tuple[AxisNoise, ...],
    skip: int,
    cal_mean: FloatArray,
    cal_sd: FloatArray,
) -> _Folds:
    grams = []
    for k in range(int(fold.max()) + 1):
        ik = index[fold == k]
        grams.append(
            whitened_grams(data, ik, run_starts(data, ik, step), forms, [noise], skip=skip)[0]
        )
    total = grams[0]
    for g in grams[1:]:
        total = _plus(total, g)
    held = [augment(g, cal_mean, cal_sd, 0.0) for g in grams]
    rest = [augment(_minus(total, g), cal_mean, cal_sd, 0.0) for g in grams]
    return _Folds(held, rest)


def _score(folds: _Folds, forms: Sequence[Form]) -> float:
    """Summed whitened squared error on each fold of the model ``forms`` fitted on the rest."""
    cols = np.arange(12)
    if forms:
        cols = np.r_[
            cols, 12 + np.concatenate([np.arange(f.cols.start, f.cols.stop) for f in forms])
        ]
    total = 0.0
    for held, rest in zip(folds.held, folds.rest, strict=True):
        _, theta = model_evidence(rest, forms)
        g, b = held.g[np.ix_(cols, cols)], held.b[cols]
        total += held.q - 2.0 * float(theta @ b) + float(theta @ g @ theta)
    return total


def cross_validated(
    data: DiagnosisData,
    train: BoolArray,
    chosen: Sequence[Form],
    noise: tuple[AxisNoise, ...],
    *,
    skip: int,
    cal_mean: FloatArray,
    cal_sd: FloatArray,
    outside: Callable[[IntArray], BoolArray] | None = None,
) -> CrossValidation:
    """Backward elimination of the chosen model's effects by their orbit-fold gain (see the
    module). ``chosen``'s forms must have columns side by side from 0 (``core._compact``).
    ``outside(index)``, when given, keeps the training samples it marks (the core's: those
    outside the events of the effects fitted beside the chosen model, a field that no fold's
    fit forecasts)."""
    from orbitcal.diagnose.blocked import estimation_samples

    names = tuple(f.effect for f in chosen)
    index = estimation_samples(train)
    if outside is not None:
        index = index[outside(index)]
    if not chosen or index.size < 2:
        return CrossValidation(0, kept=names)
    fold = orbit_folds(data.t_utc_s[index], orbital_period_s(data))
    if int(fold.max()) < 1:
        return CrossValidation(0, kept=names)
    step = int(np.median(np.diff(index)))
    folds = _fold_grams(data, index, fold, step, chosen, noise, skip, cal_mean, cal_sd)
    model = list(chosen)
    gain: dict[str, float] = {}
    withdrawn: list[str] = []
    while model:
        with_all = _score(folds, model)
        gains = {
            f.effect: _score(folds, [g for g in model if g is not f]) - with_all for f in model
        }
        gain.update(gains)
        worst = min(gains, key=lambda e: gains[e])
        if gains[worst] > 0.0:
            break
        withdrawn.append(worst)
        model = [f for f in model if f.effect != worst]
    return CrossValidation(
        int(fold.max()) + 1, gain, tuple(f.effect for f in model), tuple(withdrawn)
    )
