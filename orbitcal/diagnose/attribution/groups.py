"""Group steps of the selection: a pair, or three effects, that pass together when no single
candidate does (:class:`GroupSelection`), with the screen that ranks pairs by one weighted solve.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.attribution.joint_fit import (
    JointFit,
    _box_solve,
    _calibration_prior_terms,
    _effect_priors,
    _resolve,
    _robust_sigma,
    _scaled_bounds,
    fit_joint,
)
from orbitcal.diagnose.attribution.selection import (
    PAIR_SCREEN_GAIN,
    PAIR_SCREEN_MARGIN,
    PAIR_SCREEN_SAMPLES,
    TRIPLE_PAIRS,
    Candidate,
    Selection,
)
from orbitcal.diagnose.attribution.significance import _chunk_test
from orbitcal.diagnose.blocked import BlockedDesign
from orbitcal.diagnose.effects import (
    DesignBlock,
)
from orbitcal.metrics import norm_rms_nt


class GroupSelection(Selection):
    """The selection with its group steps: :meth:`pair` and :meth:`triple`."""

    def pair(
        self,
        fixed: Sequence[DesignBlock],
        options: Sequence[Candidate],
        r_before: FloatArray,
        rms_before: float,
    ) -> tuple[Candidate, Candidate] | None:
        """Two effects that pass together when neither passes alone.

        Two effects present at once can each leave the other's misfit in a single-effect fit
        (a thermal offset and a bias step), so that neither single fit passes the held-out test
        while both together do. Every pair of ``options`` (fitted after ``fixed``, variants as
        chosen alone) is fitted jointly; a pair passes when it shrinks the held-out residual
        significantly (Bonferroni over the pairs) and each member does so on top of the other.
        The pair with the lowest held-out RMS is returned, in order of their single RMS.
        """
        from itertools import combinations

        pairs = list(combinations(sorted(options, key=lambda c: c.holdout_rms_nt), 2))
        if not pairs:
            return None
        level = self.alpha / len(pairs)
        # Screen: every pair fitted once with the robust weights of the model without them (one
        # pass each instead of a reweighted fit); only pairs whose screened held-out RMS could
        # gain are fitted in full, best first, until the rest cannot beat the best that passed.
        # A member whose design is a scan of the residual (the attitude periods) is scanned again
        # beside its partner: alone it took its periods from a residual the partner's field
        # still fills.
        in_residual = {c.name for c in self._in_residual(options, r_before)}
        pairs = [self._pair_beside(fixed, a, b, in_residual) for a, b in pairs]
        self.screen_huber_weights(r_before)
        rms_screen = self.screen_pairs(fixed, [(a.block, b.block) for a, b in pairs])
        screened = sorted(
            ((rms, a, b) for rms, (a, b) in zip(rms_screen, pairs, strict=True)),
            key=lambda t: t[0],
        )
        could_gain = rms_before * (1.0 - self.min_gain * PAIR_SCREEN_GAIN)
        best: tuple[float, Candidate, Candidate] | None = None
        for approx, a, b in screened:
            if approx >= could_gain:
                break
            if best is not None and approx > best[0] * (1.0 + PAIR_SCREEN_MARGIN):
                break
            fit, r, rms = self.fit([*fixed, a.block, b.block])
            ok = self._pair_passes(fit, r, rms, a, b, r_before, rms_before, level)
            if not ok:
                # Each member's form was chosen alone, with the partner's field in the residual
                # (a step time, an attitude error's periods): chosen again beside each other.
                again = self._beside_each_other(fixed, [a, b])
                if again is not None:
                    (a, b), fit, r, rms = again
                    ok = self._group_passes(fixed, [a, b], fit, r, rms, r_before, rms_before, level)
            if ok and (best is None or rms < best[0]):
                best = (rms, a, b)
        return None if best is None else (best[1], best[2])

    def _in_residual(self, options: Sequence[Candidate], r_before: FloatArray) -> list[Candidate]:
        """The candidates whose own fit takes at least ``min_gain`` of the training residual sum
        of squares of ``r_before``: their field is in the residual."""
        rss_before = float(np.sum(r_before[self.train] ** 2))
        return [
            c
            for c in options
            if float(np.sum(c.residual_nt[self.train] ** 2)) < (1.0 - self.min_gain) * rss_before
        ]

    def _pair_passes(
        self,
        fit: JointFit,
        r: FloatArray,
        rms: float,
        a: Candidate,
        b: Candidate,
        r_before: FloatArray,
        rms_before: float,
        level: float,
    ) -> bool:
        """Whether the pair's joint fit passes: inside the ranges, a significant shrink, and
        each member on top of the other (a's own test compares b alone, b's residual, with
        both)."""
        if not self._shrinks_inside(fit, r, rms, 2, r_before, rms_before, level):
            return False
        tests = [
            self.judge(fit, r, other.residual_nt, rms, other.holdout_rms_nt, k=k)
            for k, other in ((-2, b), (-1, a))
        ]
        return all(p < level and gains for p, gains in tests)

    def _shrinks_inside(
        self,
        fit: JointFit,
        r: FloatArray,
        rms: float,
        n: int,
        r_before: FloatArray,
        rms_before: float,
        level: float,
    ) -> bool:
        """Whether the last ``n`` blocks of ``fit`` are inside their ranges and together shrink
        the held-out residual by ``min_gain``, significantly at ``level`` (chunk test)."""
        if any(fit.at_bounds(len(fit.blocks) - 1 - k) for k in range(n)):
            return False
        if not self.gains(rms, rms_before):
            return False
        return bool(_chunk_test(r_before[self.holdout], r[self.holdout], self.n_chunks)[0] < level)

    def _group_passes(
        self,
        fixed: Sequence[DesignBlock],
        members: Sequence[Candidate],
        fit: JointFit,
        r: FloatArray,
        rms: float,
        r_before: FloatArray,
        rms_before: float,
        level: float,
    ) -> bool:
        """Whether effects fitted jointly after ``fixed`` pass as a group: inside their ranges,
        a significant shrink of the held-out residual, and each member significant on top of
        all the others (refitted without it)."""
        n = len(members)
        if not self._shrinks_inside(fit, r, rms, n, r_before, rms_before, level):
            return False
        for k in range(n):
            rest = [m.block for j, m in enumerate(members) if j != k]
            _, r_k, rms_k = self.fit([*fixed, *rest])
            p, gains = self.judge(fit, r, r_k, rms, rms_k, k=len(fixed) + k)
            if not (p < level and gains):
                return False
        return True

    def _beside_each_other(
        self, fixed: Sequence[DesignBlock], members: Sequence[Candidate], rounds: int = 2
    ) -> tuple[list[Candidate], JointFit, FloatArray, float] | None:
        """The members with each one's form chosen again beside the others: the variant by
        training BIC (:func:`_resolve`), an effect rescanned beside others scanned again, in
        turn, ``rounds`` times or until nothing changes; and their joint fit. ``None`` when no
        form changes."""
        out = list(members)
        changed = False
        for _ in range(rounds):
            moved = False
            for k, c in enumerate(out):
                beside = [m.block for j, m in enumerate(out) if j != k]
                if self.rescanned(c.name):
                    chosen = self.design_beside(c.name, [*fixed, *beside])
                elif self.designs[c.name].alternatives:
                    chosen = _resolve(
                        self.data,
                        self.train,
                        [*fixed, *beside],
                        self.designs[c.name],
                        robust=self.robust,
                    )
                else:
                    continue
                if chosen is not c.block and chosen.variant != c.block.variant:
                    out[k] = dataclasses.replace(c, design=chosen)
                    moved = True
            if not moved:
                break
            changed = True
        if not changed:
            return None
        fit, r, rms = self.fit([*fixed, *(c.block for c in out)])
        return out, fit, r, rms

    def triple(
        self,
        fixed: Sequence[DesignBlock],
        options: Sequence[Candidate],
        r_before: FloatArray,
        rms_before: float,
    ) -> tuple[Candidate, Candidate, Candidate] | None:
        """Three effects that pass together when no single effect and no pair passes.

        Beside two others, an effect can leave its range in every single and pair fit (a
        nonlinearity's cross-track terms, ill-determined in a nadir attitude, take up whatever
        field is left), and an attitude error's periods scanned on a residual that two other
        effects still fill are wrong. Among the candidates whose own fits take ``min_gain`` of
        the training residual, the triples and the pairs are screened (:meth:`screen_pairs`);
        the ``TRIPLE_PAIRS`` best triples are fitted, and beside each of the ``TRIPLE_PAIRS``
        best pairs an effect rescanned beside others is scanned again. A triple passes as
        :meth:`_group_passes` (Bonferroni over every triple that could have been screened) --
        with each member's form chosen again beside the others if it fails as chosen alone.
        The triple with the lowest held-out RMS is returned.
        """
        from itertools import combinations

        scanned = [n for n in self.designs if n in self.effects and self.rescanned(n)]
        others = sorted(
            (c for c in self._in_residual(options, r_before) if not self.rescanned(c.name)),
            key=lambda c: c.holdout_rms_nt,
        )
        pairs = list(combinations(others, 2)) if scanned else []
        triples = list(combinations(others, 3))
        if not pairs and not triples:
            return None
        level = self.alpha / (len(pairs) * len(scanned) + len(triples))
        self.screen_huber_weights(r_before)
        groups: list[list[Candidate]] = []
        if triples:
            rms_t = self.screen_pairs(fixed, [[c.block for c in t] for t in triples])
            ranked_t = sorted(zip(rms_t, triples, strict=True), key=lambda x: x[0])
            groups += [list(t) for v, t in ranked_t[:TRIPLE_PAIRS] if v < rms_before]
        if pairs:
            rms_p = self.screen_pairs(fixed, [(a.block, b.block) for a, b in pairs])
            ranked_p = sorted(zip(rms_p, pairs, strict=True), key=lambda x: x[0])
            for v, (a, b) in ranked_p[:TRIPLE_PAIRS]:
                if v >= rms_before:
                    break
                for name in scanned:
                    block = self.design_beside(name, [*fixed, a.block, b.block])
                    fit, r, rms = self.fit([*fixed, a.block, b.block, block])
                    groups.append([a, b, Candidate(name, fit, r, rms, design=block)])
        best: tuple[float, list[Candidate]] | None = None
        for members in groups:
            last = members[-1]
            if last.design is not None and self.rescanned(last.name):
                fit, r, rms = last.fit, last.residual_nt, last.holdout_rms_nt  # fitted with all
            else:
                fit, r, rms = self.fit([*fixed, *(c.block for c in members)])
            ok = self._group_passes(fixed, members, fit, r, rms, r_before, rms_before, level)
            if not ok:
                again = self._beside_each_other(fixed, members)
                if again is not None:
                    members, fit, r, rms = again
                    ok = self._group_passes(
                        fixed, members, fit, r, rms, r_before, rms_before, level
                    )
            if ok and (best is None or rms < best[0]):
                best = (rms, members)
        if best is None:
            return None
        a, b, s = best[1]
        return a, b, s

    def _pair_beside(
        self, fixed: Sequence[DesignBlock], a: Candidate, b: Candidate, in_residual: set[str]
    ) -> tuple[Candidate, Candidate]:
        """The pair with a member rescanned beside others designed beside ``fixed`` and the other
        member (its single fit and test kept: the pair's own tests judge it).

        Only beside a partner in ``in_residual`` (its own fit takes ``min_gain`` of the training
        residual sum of squares at least): a partner whose field is not in the residual leaves
        the scan where it was (on a noise-level day at 1 Hz, ten scans for nothing).
        """
        out = [a, b]
        for k, (c, other) in enumerate(((a, b), (b, a))):
            if (
                self.rescanned(c.name)
                and not self.rescanned(other.name)
                and other.name in in_residual
            ):
                again = self.design_beside(c.name, [*fixed, other.block])
                if again is not c.block:
                    out[k] = dataclasses.replace(c, design=again)
        return out[0], out[1]

    def screen_huber_weights(self, r_before: FloatArray) -> None:
        """Fixed Huber weights of the screen (k = 2.5 sigma, as :func:`fit_joint`) from the
        residual of the model without the screened effects, and the screen's samples: every
        k-th training and held-out sample, at most ``PAIR_SCREEN_SAMPLES`` of each."""
        sigma = _robust_sigma(r_before[self.train])
        u = np.abs(r_before) / (2.5 * sigma)
        self._screen_weights = np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-12))
        idx = np.flatnonzero(self.train)
        step = max(1, -(-idx.size // PAIR_SCREEN_SAMPLES))
        mask = np.zeros_like(self.train)
        mask[idx[::step]] = True
        self._screen_train = mask
        held = np.flatnonzero(self.holdout)
        self._screen_holdout = held[:: max(1, -(-held.size // PAIR_SCREEN_SAMPLES))]

    def screen_pairs(
        self, fixed: Sequence[DesignBlock], pairs: Sequence[Sequence[DesignBlock]]
    ) -> list[float]:
        """Held-out RMS of ``fixed`` plus each pair, each fitted once with the screen's fixed
        weights, all from two Gram matrices.

        One pass over the screen's training samples forms the weighted normal equations of the
        calibration, ``fixed`` and every block of the pairs; one over its held-out samples the
        unweighted ones. A pair's fit is then the solve of its rows and columns (with the ridge,
        the bounds and the priors of :func:`fit_joint`), and its held-out residual sum of squares
        ``y'y - 2 t'X'y + t'X'X t``: the cost of 55 pairs is that of one fit. The priors' noise
        level is each pair's own, as :func:`fit_joint` takes it (one residual pass per pair that has
        a prior).
        """
        assert self._screen_weights is not None and self._screen_train is not None
        extra: list[DesignBlock] = []
        for pair in pairs:
            for bl in pair:
                if not any(bl is e for e in extra):
                    extra.append(bl)
        design = BlockedDesign(self.data, [*fixed, *extra])
        scale = design.scale
        cols_of: dict[int, npt.NDArray[np.intp]] = {}
        col = 12 + sum(bl.width for bl in fixed)
        for bl in extra:
            cols_of[id(bl)] = np.arange(col, col + bl.width)
            col += bl.width
        base_cols = np.arange(12 + sum(bl.width for bl in fixed))
        index = np.flatnonzero(self._screen_train)
        y = self.data.b_raw_nt[index].reshape(-1)
        w = np.asarray(self._screen_weights[index], dtype=float).reshape(-1)
        gram, rhs_data = design.normal_equations(index, y, w)
        n_rows = y.size
        p_all = design.p
        ridge = np.r_[np.full(12, 1e-10), np.full(p_all - 12, 1e-5)] * n_rows
        # Held-out sums about a reference fit (the model without the pair, plain weighted least
        # squares): y'y - 2 t'X'y + t'X'X t of the raw field (~5e4 nT) against a residual of
        # a few nT would lose eight digits to cancellation.
        held = self._screen_holdout
        theta_ref = np.zeros(p_all)
        sub = np.ix_(base_cols, base_cols)
        theta_ref[base_cols] = np.linalg.lstsq(
            gram[sub] + np.diag(ridge[base_cols]), rhs_data[base_cols], rcond=1e-13
        )[0]
        y_h = self.data.b_raw_nt[held].reshape(-1)
        r_h = design.residual(held, y_h, theta_ref)
        gram_h, rhs_h = design.normal_equations(held, y_h, np.ones_like(y_h))
        rhs_h = rhs_h - gram_h @ theta_ref
        rr_h = float(r_h @ r_h)
        pm, pp = _effect_priors(design.blocks, scale)
        prior = self.data.calibration_prior
        plain: tuple[FloatArray, FloatArray] | None = None
        if prior is not None or np.any(pp > 0.0):
            plain = design.normal_equations(index, y, np.ones_like(y))
        lo_all, hi_all = _scaled_bounds(design.blocks, scale)
        out = []
        for group in pairs:
            cols = np.concatenate([base_cols, *(cols_of[id(bl)] for bl in group)])
            sub = np.ix_(cols, cols)
            prior_mean = np.zeros(cols.size)
            prior_precision = np.zeros(cols.size)
            if plain is not None and (prior is not None or np.any(pp[cols] > 0.0)):
                # the priors' noise level as fit_joint takes it: the residual of the same model
                # by plain least squares (one pass over the screen's samples)
                theta0 = np.linalg.lstsq(plain[0][sub], plain[1][cols], rcond=1e-13)[0]
                r0 = BlockedDesign(self.data, [*fixed, *group]).residual(index, y, theta0)
                noise = _robust_sigma(r0)
                if prior is not None:
                    prior_mean[:12], prior_precision[:12] = _calibration_prior_terms(prior, scale)
                    prior_precision *= noise**2
                prior_mean = np.where(pp[cols] > 0.0, pm[cols], prior_mean)
                prior_precision = prior_precision + pp[cols] * noise**2
            normal = gram[sub] + np.diag(ridge[cols] + prior_precision)
            rhs = rhs_data[cols] + prior_precision * prior_mean
            try:
                theta = np.linalg.solve(normal, rhs)
            except np.linalg.LinAlgError:  # pragma: no cover - singular design
                theta = np.linalg.lstsq(normal, rhs, rcond=None)[0]
            if lo_all is not None and hi_all is not None:
                lo, hi = lo_all[cols], hi_all[cols]
                if np.any(theta < lo) or np.any(theta > hi):
                    theta = _box_solve(normal, rhs, lo, hi, theta)
            d = theta - theta_ref[cols]
            rss = rr_h - 2.0 * float(d @ rhs_h[cols]) + float(d @ gram_h[sub] @ d)
            out.append(float(np.sqrt(max(rss, 0.0) / held.size)))
        return out

    def screen_rms(self, fixed: Sequence[DesignBlock], extra: Sequence[DesignBlock]) -> float:
        """Held-out RMS of ``fixed + extra`` fitted once with the screen's fixed weights (one
        :func:`fit_joint`: the reference :meth:`screen_pairs` equals, pair by pair)."""
        assert self._screen_weights is not None and self._screen_train is not None
        blocks = [*fixed, *extra]
        fit = fit_joint(
            self.data, self._screen_train, blocks, robust=False, weights=self._screen_weights
        )
        idx = self._screen_holdout
        pred = self.data.b_ref_body_nt[idx] @ fit.a.T + fit.o_nt
        for k, bl in enumerate(fit.blocks):
            pred += bl.rows(idx) @ fit.coef[k]
        return norm_rms_nt(self.data.b_raw_nt[idx] - pred)
