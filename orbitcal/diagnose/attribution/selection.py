"""The selection's core: one candidate fitted beside the selected effects and judged on held-out
chunks (:class:`Candidate`, :class:`Selection`), the choice among tied candidates, near twins
and the backward step.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray, IntArray
from orbitcal.diagnose.attribution.joint_fit import (
    JointFit,
    _bic,
    _resolve,
    _twins,
    fit_joint,
    leaves_range,
)
from orbitcal.diagnose.attribution.significance import _chunk_test, _support
from orbitcal.diagnose.attribution.uncertainty import _autocorr_inflation
from orbitcal.diagnose.effects import (
    DesignBlock,
    DiagnosisData,
    Effect,
    get_effect,
)
from orbitcal.metrics import norm_rms_nt

_T = TypeVar("_T")
_R = TypeVar("_R")


@dataclass(frozen=True)
class Candidate:
    """One candidate fitted jointly with the calibration and the effects already selected.

    Attributes
    ----------
    name : str
        Catalogue name.
    fit : JointFit
        The joint fit; the candidate's block is the last one.
    residual_nt : ndarray, shape (N, 3)
        Residual of that fit at every sample [nT].
    holdout_rms_nt : float
        Held-out vector RMS of the residual [nT].
    p_value : float
        Held-out chunk test against the model without the candidate (1 when not tested).
    gains : bool
        Whether it shrinks the held-out residual by the minimum gain (:meth:`Selection.judge`).
    """

    name: str
    fit: JointFit
    residual_nt: FloatArray
    holdout_rms_nt: float
    p_value: float = 1.0
    gains: bool = False
    design: DesignBlock | None = None

    def passes(self, level: float) -> bool:
        """Significant at ``level`` and shrinking the held-out residual enough."""
        return self.p_value < level and self.gains

    @property
    def block(self) -> DesignBlock:
        """The candidate's design block: the variant chosen on the training blocks, or the
        ``design`` found beside a pair's partner (:meth:`Selection.pair`)."""
        return self.design if self.design is not None else self.fit.blocks[-1]


#: Tied candidates (held-out chunks cannot tell them apart) whose training BIC exceeds the
#: winner's by less than this are reported as indistinguishable from it: a BIC difference below
#: 10 (2 ln of the Bayes factor) is not "very strong" evidence (Kass & Raftery 1995).
NEAR_TWIN_BIC = 10.0

#: The pair step fits in full only pairs whose screened held-out RMS (one weighted solve,
#: :meth:`GroupSelection.screen_pairs`) shrinks by this fraction of ``min_gain`` at least, and
#: stops once the screened RMS exceeds the best full fit that passed by ``PAIR_SCREEN_MARGIN``.
#: Measured on the 36 pairs of the first 16 compound-benchmark worlds (seed 1): screened and
#: full held-out RMS differ by 0.054 % at most (the weights of a model one effect short are
#: close to the final ones), far inside both margins. [-]
PAIR_SCREEN_GAIN = 0.5
PAIR_SCREEN_MARGIN = 0.02
#: The screen fits every k-th training sample and scores every k-th held-out one, at most this
#: many of each (the full fits that follow use them all).
PAIR_SCREEN_SAMPLES = 20_000

#: Candidates whose held-out RMS is within this fraction of the best one and that the held-out
#: chunk test cannot tell worse than it are tied too (the training BIC decides among them) [-].
TIE_MAX_GAP = 0.10

#: The best screened triples :meth:`Selection.triple` fits, and the best screened pairs beside
#: which it scans an attitude error again.
TRIPLE_PAIRS = 3


@dataclass
class Selection:
    """The shared state of the selection steps of :func:`attribute` (one data set, one split).

    Every step fits on the training blocks only; the held-out blocks judge.
    """

    data: DiagnosisData
    train: BoolArray
    holdout: BoolArray
    designs: dict[str, DesignBlock]
    effects: dict[str, Effect] = field(default_factory=dict)
    robust: bool = True
    n_chunks: int = 32
    n_chunks_local: int = 16
    alpha: float = 0.05
    min_gain: float = 0.03
    tie_tolerance: float = 0.01
    workers: int = 1
    _beside: dict[tuple[Any, ...], tuple[list[DesignBlock], DesignBlock]] = field(
        default_factory=dict, repr=False
    )
    _screen_weights: FloatArray | None = field(default=None, repr=False)
    _screen_train: BoolArray | None = field(default=None, repr=False)
    _screen_holdout: IntArray = field(
        default_factory=lambda: np.zeros(0, dtype=np.intp), repr=False
    )

    def map(self, fn: Callable[[_T], _R], items: Sequence[_T]) -> list[_R]:
        """``[fn(x) for x in items]``, on up to :attr:`workers` threads (at most the machine's
        cores) when there are several items: the candidates of a step are fitted independently
        (NumPy and BLAS release the interpreter while they work), in the order given back."""
        workers = min(self.workers, len(items), os.cpu_count() or 1)
        if workers <= 1:
            return [fn(x) for x in items]
        with ThreadPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(fn, items))

    def effect(self, name: str) -> Effect:
        """The catalogue entry of candidate ``name`` (this selection's, else the catalogue's)."""
        return self.effects[name] if name in self.effects else get_effect(name)

    def rescanned(self, name: str) -> bool:
        """Whether ``name``'s design is scanned again beside the selected effects
        (:attr:`Effect.rescanned_beside_others`)."""
        return self.effect(name).rescanned_beside_others

    def evaluate(
        self, fixed: Sequence[DesignBlock], block: DesignBlock, *, bounded: bool = True
    ) -> tuple[JointFit, FloatArray, float]:
        """Fit ``block`` (its variant chosen by training BIC) with ``fixed``; residual and RMS."""
        chosen = _resolve(self.data, self.train, fixed, block, bounded=bounded, robust=self.robust)
        return self.fit([*fixed, chosen], bounded=bounded)

    def fit(
        self, blocks: Sequence[DesignBlock], *, bounded: bool = True
    ) -> tuple[JointFit, FloatArray, float]:
        """Joint fit of ``blocks`` as they are; residual at every sample and held-out RMS."""
        fit = fit_joint(self.data, self.train, blocks, robust=self.robust, bounded=bounded)
        r = self.data.b_raw_nt - fit.predict_nt(self.data)
        return fit, r, norm_rms_nt(r[self.holdout])

    def test(self, fit: JointFit, r: FloatArray, r_before: FloatArray, k: int = -1) -> float:
        """p-value of the held-out chunk test of block ``k`` of ``fit`` (default the last)."""
        return self.judge(fit, r, r_before, k=k)[0]

    def judge(
        self,
        fit: JointFit,
        r: FloatArray,
        r_before: FloatArray,
        rms_after: float | None = None,
        rms_before: float | None = None,
        *,
        k: int = -1,
    ) -> tuple[float, bool]:
        """Held-out chunk test of block ``k`` of ``fit``: its p-value and whether it gains enough.

        It gains enough when the held-out RMS shrinks by ``min_gain`` or, on the chunks of its
        support, the geometric mean of the per-chunk RMS shrinks by as much: beside an effect
        no model predicts well (auroral currents that change from pass to pass) a real effect
        shrinks most chunks clearly and the total RMS hardly.
        """
        sup, chunks = _support(
            fit, self.train, self.holdout, self.n_chunks, self.n_chunks_local, k=k
        )
        p, mean_log = _chunk_test(r_before[sup], r[sup], chunks)
        ok = float(np.exp(-0.5 * mean_log)) < 1.0 - self.min_gain
        if rms_after is not None and rms_before is not None:
            ok = ok or self.gains(rms_after, rms_before)
        return p, ok

    def gains(self, rms_after: float, rms_before: float) -> bool:
        """Whether the held-out RMS shrinks by at least ``min_gain``."""
        return rms_after < rms_before * (1.0 - self.min_gain)

    def candidate(
        self,
        fixed: Sequence[DesignBlock],
        name: str,
        r_before: FloatArray,
        fixed_fit: JointFit | None = None,
        rms_before: float | None = None,
    ) -> Candidate:
        """Candidate ``name`` fitted after ``fixed`` and tested against ``r_before``.

        ``fixed_fit`` is the fit of ``fixed`` alone: an effect rescanned beside others
        (:meth:`rescanned`) is then designed again beside the fixed effects (their regressors
        projected out with the calibration's in its scan, :attr:`Effect.design_beside`), or else
        on the raw data less their fitted fields.
        """
        block = self.design_beside(name, fixed, fixed_fit)
        fit, r, rms = self.evaluate(fixed, block)
        if rms_before is None:
            rms_before = norm_rms_nt(r_before[self.holdout])
        p, ok = self.judge(fit, r, r_before, rms, rms_before)
        return Candidate(name, fit, r, rms, p, ok)

    def design_beside(
        self, name: str, fixed: Sequence[DesignBlock], fixed_fit: JointFit | None = None
    ) -> DesignBlock:
        """The design of ``name`` beside ``fixed``: for an effect rescanned beside others
        (:meth:`rescanned`), its scan again with their regressors projected out with the
        calibration's (:attr:`Effect.design_beside`), or else on the raw data less their fitted
        fields (``fixed_fit``, the fit of ``fixed`` alone; fitted here when not given); for any
        other effect, or without ``fixed``, its design on the raw data."""
        block = self.designs[name]
        if name not in self.effects or not self.effects[name].rescanned_beside_others or not fixed:
            return block
        key = (name, *(id(b) for b in fixed))
        if key in self._beside:  # the same effects again (forward, swap and pair steps)
            return self._beside[key][1]
        effect = self.effects[name]
        if effect.build_beside is not None:
            again = effect.design_beside(self.data, self.train, fixed)
        else:
            if fixed_fit is None:
                fixed_fit = self.fit(fixed)[0]
            others = sum(
                (fixed_fit.effect_nt(k) for k in range(len(fixed_fit.blocks))),
                np.zeros_like(self.data.b_raw_nt),
            )
            less = dataclasses.replace(self.data, b_raw_nt=self.data.b_raw_nt - others)
            again = effect.design(less, self.train)
        out = again if again is not None and again.all_finite() else block
        self._beside[key] = (list(fixed), out)  # the blocks kept alive: their ids stay theirs
        return out

    def implausible_reason(
        self,
        fixed: Sequence[DesignBlock],
        cand: Candidate,
        level: float,
        rms_before: float,
        r_before: FloatArray,
    ) -> str | None:
        """Why a candidate is implausible: its fit runs into the edge of a physical range.

        The free (unbounded) fit then puts a parameter outside its range: the model explains
        the data only with unphysical values, whether or not its edge-of-range fit passes the
        held-out test.
        """
        found = leaves_range(
            self.data,
            self.train,
            cand.fit,
            cand.residual_nt,
            robust=self.robust,
            blocks=[*fixed, cand.block],
        )
        if found is None:
            return None
        free, r_free, outside = found
        rms_free = norm_rms_nt(r_free[self.holdout])
        p_free, gains_free = self.judge(free, r_free, r_before, rms_free, rms_before)
        wins = p_free < level and gains_free
        how = "wins only by leaving" if wins else "its fit runs out of"
        return (
            f"{how} its physical range: "
            + "; ".join(outside)
            + f" (held-out vector RMS {rms_free:.3g} nT so, {rms_before:.3g} nT before)"
        )

    def pick(self, passing: Sequence[Candidate]) -> tuple[Candidate, list[str]]:
        """The winner among candidates that pass a step, and the models indistinguishable from it.

        Lowest held-out RMS wins; candidates within ``tie_tolerance`` of it, or within
        ``TIE_MAX_GAP`` and not significantly worse on the held-out chunks (a flexible model
        standing in for a simpler one, e.g. a 9-parameter orbit error for a time-tag error), are
        tied and separated by the Bayesian information criterion of the training fit.
        """
        top = min(passing, key=lambda c: c.holdout_rms_nt)
        best_rms = top.holdout_rms_nt
        hold = self.holdout
        tied = [
            c
            for c in passing
            if c.holdout_rms_nt <= best_rms * (1.0 + self.tie_tolerance)
            or (
                c.holdout_rms_nt <= best_rms * (1.0 + TIE_MAX_GAP)
                and _chunk_test(c.residual_nt[hold], top.residual_nt[hold], self.n_chunks)[0]
                >= self.alpha
            )
        ]
        # The BIC counts the training residuals as independent only as far as they are: the
        # autocorrelation of the best held-out model's training residual sets the effective
        # number for every tied model alike.
        if len(tied) > 1:
            r_top = top.residual_nt[self.train]
            inflation = max(_autocorr_inflation(r_top[:, i]) for i in range(3))
        else:
            inflation = 1.0
        bic = {c.name: _bic(c.fit, c.residual_nt, self.train, inflation) for c in tied}
        best = min(tied, key=lambda c: bic[c.name])
        # Models the data cannot tell apart are reported with the one named (e.g. under steady
        # attitude rates a time-tag error and an along-track orbit error differ only by the
        # Earth's rotation once the 12 parameters absorb the attitude term).
        twins = sorted(
            c.name
            for c in tied
            if c.name != best.name
            and (
                _twins(c.fit, c.residual_nt, best.fit, best.residual_nt, self.train)
                or bic[c.name] - bic[best.name] < NEAR_TWIN_BIC
            )
        )
        return best, twins

    def near_twins(self, chosen: Sequence[Candidate]) -> dict[str, str]:
        """For each selected effect with a near twin (:attr:`Effect.near_twin`) not selected: the
        partner, if the final model with the effect replaced by the partner's simplest form
        (beside the same other effects) is not worse on the held-out blocks (within
        ``TIE_MAX_GAP`` and not significantly by the chunk test), or if the partner could hide
        beside the effect (:meth:`_inseparable`: both present, a time-tag error absorbs an
        along-track orbit error but for the Earth's rotation)."""
        names = {c.name for c in chosen}
        out: dict[str, str] = {}
        full: tuple[FloatArray, float] | None = None
        for c in chosen:
            partner = self.effect(c.name).near_twin
            if partner is None or partner in names or partner not in self.designs:
                continue
            if full is None:
                _, r_full, rms_full = self.fit([x.block for x in chosen])
                full = (r_full, rms_full)
            base = self.designs[partner]
            simple = DesignBlock(base.source, base.names, base.variant, effect=base.effect)
            others = [x.block for x in chosen if x is not c]
            rep, r, rms = self.fit([*others, simple])
            hold = self.holdout
            if (
                rms <= full[1] * (1.0 + TIE_MAX_GAP)
                and _chunk_test(r[hold], full[0][hold], self.n_chunks)[0] >= self.alpha
            ):
                out[c.name] = partner
                continue
            if self._inseparable(others, c, rep, full):
                out[c.name] = partner
        return out

    def _inseparable(
        self,
        others: Sequence[DesignBlock],
        c: Candidate,
        rep: JointFit,
        full: tuple[FloatArray, float],
    ) -> bool:
        """Whether the partner's simplest form could hide beside the selected effect ``c``: at the
        amount that stands in for ``c`` alone (``rep``), the part of its field that the
        calibration, ``c`` and the other effects cannot take (least squares on the training
        samples) would change the held-out RMS by less than ``min_gain``; the data then cannot
        say whether the shift along the track is ``c``'s, the partner's or both. ``full`` is the
        residual and held-out RMS of the selected model."""
        k = len(rep.blocks) - 1
        field = rep.blocks[k].rows(np.arange(self.data.n)) @ rep.coef[k]
        probe = dataclasses.replace(self.data, b_raw_nt=self.data.b_ref_body_nt + field)
        fit = fit_joint(
            probe, self.train, [*others, c.block], robust=False, bounded=False, use_prior=False
        )
        orth = probe.b_raw_nt - fit.predict_nt(probe)
        r_full, rms_full = full  # the selected model (``others`` and ``c``)
        rms_with = norm_rms_nt((r_full + orth)[self.holdout])
        return bool(rms_with < rms_full * (1.0 + self.min_gain))

    def backward(self, blocks: Sequence[DesignBlock], names: Sequence[str]) -> str | None:
        """The selected effect that no longer earns its place beside the others, if any.

        Each effect is re-tested conditional on all the others (joint refit without it, held-out
        chunk test on its support, Bonferroni over the selected set, and the ``min_gain``
        shrink); the one with the largest p-value among those that fail is returned.
        """
        if len(blocks) < 2:
            return None
        full, r_full, rms_full = self.fit(blocks)
        level = self.alpha / len(blocks)
        worst: tuple[float, str] | None = None
        for k, name in enumerate(names):
            _, r_k, rms_k = self.fit([b for j, b in enumerate(blocks) if j != k])
            p, gains = self.judge(full, r_full, r_k, rms_full, rms_k, k=k)
            fails = p >= level or not gains
            if fails and (worst is None or p > worst[0]):
                worst = (p, name)
        return None if worst is None else worst[1]
