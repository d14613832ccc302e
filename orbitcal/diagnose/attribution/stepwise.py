"""Stepwise selection: forward steps, a swap pass, backward elimination and the release of a
residual-scanned effect chosen too early.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.attribution.groups import GroupSelection
from orbitcal.diagnose.attribution.joint_fit import JointFit
from orbitcal.diagnose.attribution.selection import Candidate
from orbitcal.diagnose.attribution.significance import _chunk_test
from orbitcal.diagnose.design import DesignBlock
from orbitcal.metrics import norm_rms_nt


@dataclass
class Stepwise:
    """The state the selection's steps share (one data set, one split), and the steps.

    Attributes
    ----------
    sel : GroupSelection
        The fits and tests of the candidates.
    single : dict of str to Candidate
        Each candidate fitted alone with the calibration (the first forward step's scores).
    base_rms : float
        Held-out RMS of the calibration alone [nT].
    r_base : ndarray, shape (N, 3)
        Residual of the calibration alone [nT].
    max_steps : int
        At most this many effects are selected.
    implausible : dict of str to str
        The latest reason each candidate was implausible at a step (updated by the steps).
    chosen : list of Candidate
        The selected candidates in selection order.
    twins : dict of str to list of str
        The candidates indistinguishable from each selected one.
    dropped : list of str
        Names dropped by the backward step (they do not re-enter).
    last_step : dict of str to dict
        The candidates of the latest forward step at which none passed, fitted beside the
        effects then chosen (:attr:`last_step_beside`): what came closest to explaining what the
        selection left. Numbers only (no residuals are held): ``holdout_rms_nt`` (vector),
        ``p_value``, the step's ``level`` (Bonferroni over its candidates), ``gains`` and
        ``implausible`` (the reason, or None).
    last_step_beside : list of str
        The effects chosen at that step.
    """

    sel: GroupSelection
    single: dict[str, Candidate]
    base_rms: float
    r_base: FloatArray
    max_steps: int
    implausible: dict[str, str]
    chosen: list[Candidate] = field(default_factory=list)
    twins: dict[str, list[str]] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)
    last_step: dict[str, dict[str, Any]] = field(default_factory=dict)
    last_step_beside: list[str] = field(default_factory=list)

    def run(self, rounds: int = 3) -> tuple[list[Candidate], dict[str, list[str]], list[str]]:
        """Forward steps, a swap pass, then backward elimination; again while the backward step
        drops one.

        Returns the selected candidates in selection order, the models indistinguishable from each
        (by name), and the names dropped by the backward step (they do not re-enter).
        """
        for _ in range(rounds):
            self.forward()
            self.swap()
            out = self.sel.backward([c.block for c in self.chosen], [c.name for c in self.chosen])
            if out is None:
                break
            self.chosen = [c for c in self.chosen if c.name != out]
            self.twins.pop(out, None)
            self.dropped.append(out)
        return self.chosen, self.twins, self.dropped

    def swap(self) -> None:
        """Each selected effect re-chosen given all the others (:attr:`chosen` changed in place).

        A forward step chooses beside the effects selected *before* it, so a flexible model can win
        an early step by standing in for an effect another one hides at that point (a 9-parameter
        orbit error for a time-tag error under a nonlinearity). Here every position is chosen again
        by the forward step's rule -- significant against the others alone, lowest held-out RMS,
        ties and near-ties by training BIC -- among all the candidates not selected elsewhere.
        """
        sel, chosen, twins, excluded = self.sel, self.chosen, self.twins, self.dropped
        if len(chosen) < 2:
            return
        for k in range(len(chosen)):
            others = [c.block for j, c in enumerate(chosen) if j != k]
            o_fit, r_o, rms_o = sel.fit(others)
            names_in = {c.name for j, c in enumerate(chosen) if j != k}
            pool = [n for n in sel.designs if n not in names_in and n not in excluded]
            level = sel.alpha / len(pool)
            passing = []
            for name in pool:
                cand = sel.candidate(others, name, r_o, o_fit, rms_o)
                if sel.implausible_reason(others, cand, level, rms_o, r_o) is not None:
                    continue
                if cand.passes(level):
                    passing.append(cand)
            if not passing:
                continue  # the backward step judges it
            best, tw = sel.pick(passing)
            # the same effect may come back in another variant (chosen given all the others)
            twins.pop(chosen[k].name, None)
            if tw:
                twins[best.name] = tw
            chosen[k] = best

    def forward(self) -> None:
        """Forward steps from :attr:`chosen` (extended in place) until nothing passes or
        :attr:`max_steps` are chosen.

        Each step tests every candidate not yet chosen (nor dropped) fitted jointly with the
        chosen effects, against the model without it, with Bonferroni over the candidates of the
        step (Holm's step-down over the steps). A candidate implausible at this step is skipped
        (:attr:`implausible` keeps its latest reason) and tried again at the next.
        """
        sel, chosen, twins, single = self.sel, self.chosen, self.twins, self.single
        r_base, base_rms, max_steps = self.r_base, self.base_rms, self.max_steps
        implausible, excluded = self.implausible, self.dropped
        blocks = [c.block for c in chosen]
        current_fit: JointFit | None = None
        if chosen:
            current_fit, current_r, current_rms = sel.fit(blocks)
        else:
            current_r, current_rms = r_base, base_rms
        released = False  # the scanned effects chosen again without them, once
        while len(chosen) < max_steps:
            names_in = {c.name for c in chosen}
            remaining = [n for n in sel.designs if n not in names_in and n not in excluded]
            if not remaining:
                break
            level = sel.alpha / len(remaining)
            passing: list[Candidate] = []
            tried: list[Candidate] = []

            def judged(
                name: str,
                fixed: list[DesignBlock] = blocks,
                fixed_fit: JointFit | None = current_fit,
                r: FloatArray = current_r,
                rms: float = current_rms,
                level: float = level,
            ) -> tuple[Candidate, str | None]:
                cand = single[name] if not chosen else sel.candidate(fixed, name, r, fixed_fit, rms)
                return cand, sel.implausible_reason(fixed, cand, level, rms, r)

            # each candidate fitted and judged alone (side by side on sel.workers threads)
            step: dict[str, dict[str, Any]] = {}
            for name, (cand, reason) in zip(remaining, sel.map(judged, remaining), strict=True):
                step[name] = {
                    "holdout_rms_nt": float(cand.holdout_rms_nt),
                    "p_value": float(cand.p_value),
                    "level": float(level),
                    "gains": bool(cand.gains),
                    "implausible": reason,
                }
                tried.append(cand)
                if reason is not None:
                    implausible[name] = reason
                    continue
                if cand.passes(level):
                    passing.append(cand)
            new: list[Candidate]
            if not passing:
                self.last_step, self.last_step_beside = step, [c.name for c in chosen]
            if passing:
                best, tw = sel.pick(passing)
                if tw:
                    twins[best.name] = tw
                new = [best]
            else:
                # Implausible ones too: a candidate whose fit leaves its range while the other
                # member's field is in the residual may fit inside it beside that member (the pair
                # passes only with both inside their ranges).
                group: Sequence[Candidate] | None = (
                    sel.pair(blocks, tried, current_r, current_rms)
                    if len(chosen) + 2 <= max_steps
                    else None
                )
                if group is None and len(chosen) + 3 <= max_steps:
                    # nor a pair: three effects together
                    group = sel.triple(blocks, tried, current_r, current_rms)
                # Only while some candidate still shrinks the held-out residual (out of range or
                # not significant): at the noise floor the group steps have nothing to find.
                if (
                    group is None
                    and not released
                    and any(sel.gains(c.holdout_rms_nt, current_rms) for c in tried)
                ):
                    released = True
                    again = self.released(current_r)
                    if again is not None:
                        chosen[:] = again
                        blocks = [c.block for c in chosen]
                        current_fit, current_r, current_rms = sel.fit(blocks)
                        continue
                if group is None:
                    break
                new = list(group)
            chosen.extend(new)
            blocks.extend(c.block for c in new)
            current_fit, current_r, current_rms = sel.fit(blocks)

    def released(self, current_r: FloatArray) -> list[Candidate] | None:
        """A stuck selection that holds an effect rescanned beside others, chosen again without it.

        An attitude error can pass alone at the first step with its periods scanned on a residual
        that other effects still fill; beside those wrong periods no other effect passes, alone or
        in a pair. The group steps (:meth:`Selection.pair`, then :meth:`Selection.triple`) run again
        from the selected effects less the scanned ones, with every candidate (the scanned ones
        too, scanned again beside their partners); the pair, or the triple if it beats the pair
        significantly by ``min_gain``, replaces the scanned effects when the model it makes shrinks
        the held-out residual of the current one significantly (chunk test at ``alpha``) by
        ``min_gain``. ``None`` otherwise.
        """
        sel, chosen, single, excluded = self.sel, self.chosen, self.single, self.dropped
        r_base, base_rms, max_steps = self.r_base, self.base_rms, self.max_steps
        if not any(sel.rescanned(c.name) for c in chosen):
            return None
        keep = [c for c in chosen if not sel.rescanned(c.name)]
        fixed = [c.block for c in keep]
        names = [n for n in sel.designs if n not in excluded and all(n != c.name for c in keep)]
        if keep:
            fit_k, r_k, rms_k = sel.fit(fixed)
            options = [sel.candidate(fixed, n, r_k, fit_k, rms_k) for n in names]
        else:
            r_k, rms_k = r_base, base_rms
            options = [single[n] for n in names if n in single]
        groups: list[Sequence[Candidate]] = []
        if len(keep) + 2 <= max_steps:
            pair = sel.pair(fixed, options, r_k, rms_k)
            if pair is not None:
                groups.append(pair)
        if len(keep) + 3 <= max_steps:
            triple = sel.triple(fixed, options, r_k, rms_k)
            if triple is not None:
                groups.append(triple)
        hold = sel.holdout
        best: tuple[float, FloatArray, Sequence[Candidate]] | None = None
        for g in groups:  # the pair first: the triple only if it beats the pair as a step would
            _, r, rms = sel.fit([*fixed, *(c.block for c in g)])
            if best is None or (
                sel.gains(rms, best[0])
                and _chunk_test(best[1][hold], r[hold], sel.n_chunks)[0] < sel.alpha
            ):
                best = (rms, r, g)
        if best is None:
            return None
        rms_new, r_new, group = best
        if not sel.gains(rms_new, norm_rms_nt(current_r[hold])):
            return None
        if _chunk_test(current_r[hold], r_new[hold], sel.n_chunks)[0] >= sel.alpha:
            return None
        return [*keep, *group]
