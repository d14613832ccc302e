"""The attribution's driver, :func:`attribute`: baseline, candidates, stepwise selection, scores.

The engine names no effect: what is special about one (a regional test, a scan beside others, a
near twin) is an attribute of its :class:`~orbitcal.diagnose.effects.Effect`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attribution.groups import GroupSelection
from orbitcal.diagnose.attribution.joint_fit import JointFit, fit_joint, time_blocks
from orbitcal.diagnose.attribution.scores import Attribution, EffectScore, _params
from orbitcal.diagnose.attribution.selection import Candidate
from orbitcal.diagnose.attribution.split_fits import _absorbed_by_calibration, split_fit_tests
from orbitcal.diagnose.attribution.stepwise import Stepwise
from orbitcal.diagnose.attribution.uncertainty import (
    _absorbed_fraction,
    _calibration_basis,
    _intervals,
    _shrink_interval,
    _verdict_confidence,
    contained_fraction,
    template_systematic,
    through_sensor,
)
from orbitcal.diagnose.effects import CATALOGUE, DesignBlock, DiagnosisData, Effect
from orbitcal.diagnose.options import AttributionOptions
from orbitcal.errors import NotEnoughDataError
from orbitcal.metrics import norm_rms_nt

__all__ = ["MIN_TRAIN_SAMPLES", "attribute", "training_split"]

#: Fewest training samples an attribution fits on (the 12 parameters and an effect).
MIN_TRAIN_SAMPLES = 30


def training_split(
    data: DiagnosisData,
    options: AttributionOptions = AttributionOptions(),
    fit_mask: BoolArray | None = None,
) -> tuple[BoolArray, BoolArray]:
    """The training and held-out samples of an attribution (held-out: the latest time blocks).

    Raises
    ------
    NotEnoughDataError
        Fewer than :data:`MIN_TRAIN_SAMPLES` training samples, or too few held-out samples for
        the chunk test (``2 * options.n_chunks_local``).
    """
    train, holdout, _ = time_blocks(
        data.t_utc_s, n_blocks=options.n_blocks, holdout_blocks=options.holdout_blocks
    )
    if fit_mask is not None:
        train = train & np.asarray(fit_mask, dtype=bool)
    n_train, n_holdout = int(train.sum()), int(holdout.sum())
    if n_train < MIN_TRAIN_SAMPLES or n_holdout < 2 * options.n_chunks_local:
        raise NotEnoughDataError(
            f"too few samples for held-out attribution ({n_train} training, {n_holdout} held "
            f"out; at least {MIN_TRAIN_SAMPLES} and {2 * options.n_chunks_local} needed); "
            "provide a longer time span (hours of telemetry, several orbits)"
        )
    return train, holdout


@dataclass
class _Model:
    """A fitted model with its residual at every sample and held-out RMS."""

    fit: JointFit
    residual_nt: FloatArray
    rms_nt: float


@dataclass
class _Split:
    """Where the effects are fitted and judged, and where the report's models are."""

    train: BoolArray
    holdout: BoolArray
    base: _Model
    report_train: BoolArray
    report_holdout: BoolArray
    #: The calibration on every sample when the others are judged on quiet samples only.
    report_base: _Model | None = None
    #: The effect whose regional test restricted the others to its quiet samples.
    regional: Effect | None = None


def _calibration_only(
    data: DiagnosisData, train: BoolArray, holdout: BoolArray, robust: bool
) -> _Model:
    base = fit_joint(data, train, (), robust=robust)
    r_base = data.b_raw_nt - base.predict_nt(data)
    return _Model(base, r_base, norm_rms_nt(r_base[holdout]))


def _split_for(
    data: DiagnosisData,
    candidates: Sequence[Effect],
    options: AttributionOptions,
    fit_mask: BoolArray | None,
) -> _Split:
    """The training/held-out split; restricted to an effect's quiet samples when its regional
    test finds it in the calibration's residual.

    Auroral currents that the regional test finds in the calibration's residual change from
    crossing to crossing: no model predicts their held-out part, which then swamps every other
    effect's held-out test. The other effects are fitted and judged on quiet magnetic latitudes
    only (as Swarm processing does); the currents are named by the regional test on what the
    selected model leaves.
    """
    train, holdout = training_split(data, options, fit_mask)
    base = _calibration_only(data, train, holdout, options.robust)
    split = _Split(train, holdout, base, train, holdout)
    for eff in candidates:
        if eff.regional_test is None:
            continue
        pre = eff.regional_test.run(data, base.residual_nt, [])
        quiet = eff.regional_test.quiet_mask(data)
        if (
            pre is not None
            and pre.significant
            and int((train & quiet).sum()) >= MIN_TRAIN_SAMPLES
            and int((holdout & quiet).sum()) >= 3 * options.n_chunks
        ):
            q_train, q_holdout = train & quiet, holdout & quiet
            q_base = _calibration_only(data, q_train, q_holdout, options.robust)
            return _Split(q_train, q_holdout, q_base, train, holdout, base, eff)
    return split


def _designs(
    data: DiagnosisData, candidates: Sequence[Effect], train: BoolArray
) -> dict[str, DesignBlock]:
    """The candidates whose witness is in the data, with their design blocks."""
    designs: dict[str, DesignBlock] = {}
    for eff in candidates:
        block = eff.design(data, train)
        if block is not None and block.all_finite():
            designs[eff.name] = block
    return designs


def _step_scores(
    sel: GroupSelection, selected: Sequence[str], blocks: Sequence[DesignBlock], base: _Model
) -> tuple[list[EffectScore], list[tuple[FloatArray, FloatArray]], _Model]:
    """Each selected effect scored as a step on top of the ones before it (joint refits); the
    residuals before and after each step, and the final model."""
    scores: list[EffectScore] = []
    residuals: list[tuple[FloatArray, FloatArray]] = []
    current = base
    for step, name in enumerate(selected, start=1):
        fit, r, rms = sel.fit(blocks[:step])
        p = sel.test(fit, r, current.residual_nt)
        scores.append(
            EffectScore(
                name, True, current.rms_nt, rms, p, _params(fit, len(fit.blocks) - 1), step=step
            )
        )
        residuals.append((current.residual_nt, r))
        current = _Model(fit, r, rms)
    return scores, residuals, current


def _unique_contributions(
    sel: GroupSelection,
    selected: Sequence[str],
    blocks: Sequence[DesignBlock],
    base_rms: float,
    final_rms: float,
) -> dict[str, float]:
    """Drop-one unique contributions of the selected set [nT of held-out RMS]."""
    if len(selected) == 1:
        return {selected[0]: base_rms - final_rms}
    unique: dict[str, float] = {}
    if len(selected) > 1:
        for k, name in enumerate(selected):
            others = [b for j, b in enumerate(blocks) if j != k]
            _, _, rms_k = sel.fit(others)
            unique[name] = rms_k - final_rms
    return unique


def _ranked_effects(
    sel: GroupSelection,
    stepwise: Stepwise,
    step_scores: Sequence[EffectScore],
    step_residuals: Sequence[tuple[FloatArray, FloatArray]],
    final: _Model,
    unique: dict[str, float],
    indistinguishable: dict[str, list[str]],
) -> list[EffectScore]:
    """The selected effects in selection order with their final joint values, then the others
    by held-out RMS (implausible ones last), each with its single fit against the baseline."""
    data, train, holdout, n_chunks = sel.data, sel.train, sel.holdout, sel.n_chunks
    single, implausible = stepwise.single, stepwise.implausible
    cal_basis = _calibration_basis(data, train)
    shown = through_sensor(data, final.fit, train, robust=sel.robust)
    effects: list[EffectScore] = []
    for k, sc in enumerate(step_scores):
        params = _params(shown, k)  # final joint values, fields at the sensor through A
        if sc.name in indistinguishable:
            params["indistinguishable_from"] = indistinguishable[sc.name]
        before_r, after_r = step_residuals[k]
        effects.append(
            EffectScore(
                sc.name,
                True,
                sc.holdout_rms_before_nt,
                sc.holdout_rms_after_nt,
                sc.p_value,
                params,
                unique_rms_increase_nt=unique.get(sc.name, 0.0),
                step=sc.step,
                intervals=_intervals(
                    shown,
                    k,
                    final.residual_nt,
                    train,
                    template_systematic(data, shown, k, train, robust=sel.robust),
                ),
                shrink_interval=_shrink_interval(before_r, after_r, holdout, n_chunks),
                absorbed_fraction=_absorbed_fraction(final.fit, k, train, cal_basis),
            )
        )
    selected = {sc.name for sc in step_scores}
    rest = sorted(
        (n for n in single if n not in selected),
        key=lambda n: (n in implausible, single[n].holdout_rms_nt),
    )
    for name in rest:
        c = single[name]
        effects.append(
            EffectScore(
                name,
                False,
                stepwise.base_rms,
                c.holdout_rms_nt,
                c.p_value,
                _params(c.fit, 0),
                implausible=implausible.get(name),
                intervals=_intervals(c.fit, 0, c.residual_nt, train),
                shrink_interval=_shrink_interval(stepwise.r_base, c.residual_nt, holdout, n_chunks),
                absorbed_fraction=_absorbed_fraction(c.fit, 0, train, cal_basis),
            )
        )
    return effects


def _selection(
    data: DiagnosisData,
    split: _Split,
    candidates: Sequence[Effect],
    options: AttributionOptions,
    excluded: Sequence[str] = (),
) -> tuple[GroupSelection, Stepwise, list[Candidate], dict[str, list[str]]]:
    """Run the stepwise selection: the selection, its state, the chosen candidates and the
    candidates indistinguishable from each (near twins included)."""
    designs = _designs(data, candidates, split.train)
    sel = GroupSelection(
        data,
        split.train,
        split.holdout,
        designs,
        effects={e.name: e for e in candidates},
        robust=options.robust,
        n_chunks=options.n_chunks,
        n_chunks_local=options.n_chunks_local,
        alpha=options.alpha,
        min_gain=options.min_gain,
        tie_tolerance=options.tie_tolerance,
        workers=options.workers,
    )
    base = split.base
    # Single-effect scores against the baseline (also the first forward step).
    names = list(designs)
    fitted = sel.map(lambda n: sel.candidate([], n, base.residual_nt, None, base.rms_nt), names)
    single = dict(zip(names, fitted, strict=True))
    # Implausible against the baseline: reported with the single fits of the candidates not
    # selected. Within the selection a candidate is judged again at every step.
    # An effect found by its regional test in the calibration's residual takes one of the
    # ``max_steps`` places: named by that test after the selection, not beside a third effect
    # that would take up what the others leave on its quiet samples.
    steps = options.max_steps - 1 if split.regional is not None else options.max_steps
    # An excluded candidate is never chosen: as one the backward step dropped.
    stepwise = Stepwise(
        sel, single, base.rms_nt, base.residual_nt, steps, {}, dropped=list(excluded)
    )
    chosen, indistinguishable, _ = stepwise.run()
    for name, partner in sel.near_twins(chosen).items():
        if partner not in indistinguishable.get(name, []):
            indistinguishable[name] = sorted([*indistinguishable.get(name, []), partner])
    return sel, stepwise, chosen, indistinguishable


def _named_regionally(
    data: DiagnosisData,
    candidates: Sequence[Effect],
    split: _Split,
    residual_nt: FloatArray,
    selected: list[str],
    effects: list[EffectScore],
    n_steps: int,
) -> tuple[list[EffectScore], list[Effect]]:
    """The effects with a regional test that find themselves in what the selected model leaves
    (``residual_nt``): appended to ``selected``, their scores placed after the ``n_steps``
    step scores in the ranked ``effects``; the new ranking and the effects so named."""
    named: list[Effect] = []
    for eff in candidates:
        if eff.regional_test is None:
            continue
        regional = eff.regional_test.run(data, residual_nt, selected)
        if regional is not None and split.regional is eff:
            regional.params["others_judged_on"] = eff.regional_test.quiet_note
        if regional is not None and regional.significant:
            effects = [e for e in effects if e.name != regional.name]
            effects.insert(n_steps, regional)
            selected.append(regional.name)
            named.append(eff)
    return effects, named


def _report_models(
    data: DiagnosisData,
    split: _Split,
    final: _Model,
    chosen_blocks: Sequence[DesignBlock],
    named_regionally: Sequence[Effect],
    options: AttributionOptions,
    chosen_names: Sequence[str],
) -> tuple[_Model, _Model, list[str]]:
    """The report's baseline and final model, and the effect of each of the final model's
    blocks. When the others were judged on an effect's quiet samples only, both on every
    sample: the calibration fitted on all training samples, and the selected effects with the
    regional effects' models fitted jointly."""
    if split.report_base is None:
        return split.base, final, list(chosen_names)
    final_blocks = list(chosen_blocks)
    names = list(chosen_names)
    for eff in named_regionally:
        block = eff.design(data, split.report_train)
        if block is not None and block.all_finite():
            final_blocks.append(block)
            names.append(eff.name)
    fit = fit_joint(data, split.report_train, final_blocks, robust=options.robust)
    r = data.b_raw_nt - fit.predict_nt(data)
    # the report's baseline: its RMS on every held-out sample
    return split.report_base, _Model(fit, r, norm_rms_nt(r[split.report_holdout])), names


def attribute(
    data: DiagnosisData,
    *,
    options: AttributionOptions = AttributionOptions(),
    candidates: Sequence[Effect] = CATALOGUE,
    fit_mask: BoolArray | None = None,
    excluded: Sequence[str] = (),
) -> Attribution:
    """Attribute the calibration residual to catalogue effects, judged on held-out later blocks.

    Stepwise selection (:class:`~orbitcal.diagnose.attribution.stepwise.Stepwise`): forward
    steps add the best candidate that shrinks the held-out residual significantly
    (:meth:`Selection.pick`; when no single candidate passes, a pair or three that pass together,
    :meth:`GroupSelection.pair`), a swap pass chooses every selected effect again given the
    others, then each is re-tested conditional on all the others and the weakest that fails is
    dropped (:meth:`Selection.backward`); forward steps resume without it. A candidate that is
    ``implausible`` at one step (its fit leaves its physical range) is tried again at the next.

    Parameters
    ----------
    data : DiagnosisData
        Time-ordered samples.
    options : AttributionOptions
        Blocks, chunks, level, gain, steps, robustness, split tests.
    candidates : sequence of Effect
        The models to try (default: the whole catalogue; those without their witness drop out).
    fit_mask : ndarray of bool, optional
        Further restricts the samples every fit may use (e.g. quiet magnetic latitudes during a
        storm); held-out scoring still uses every held-out sample.
    excluded : sequence of str
        Candidates scored alone but never selected (the review withdrew them from an earlier
        selection on these data: the second look of ``orbitcal.diagnose.api._attribute_reviewed``).

    Raises
    ------
    NotEnoughDataError
        Too few training or held-out samples (:func:`training_split`).
    """
    split = _split_for(data, candidates, options, fit_mask)
    base = split.base
    sel, stepwise, chosen, indistinguishable = _selection(
        data, split, candidates, options, excluded
    )
    implausible = stepwise.implausible
    selected = [c.name for c in chosen]
    chosen_blocks = [c.block for c in chosen]
    step_scores, step_residuals, final = _step_scores(sel, selected, chosen_blocks, base)
    for name in selected:
        implausible.pop(name, None)
    unique = _unique_contributions(sel, selected, chosen_blocks, base.rms_nt, final.rms_nt)
    effects = _ranked_effects(
        sel, stepwise, step_scores, step_residuals, final, unique, indistinguishable
    )
    single = stepwise.single
    confidence: float | None = _verdict_confidence(
        selected[0] if selected else "none",
        indistinguishable.get(selected[0], []) if selected else [],
        base.residual_nt,
        {n: v.residual_nt for n, v in single.items() if n not in implausible},
        split.holdout,
        options.n_chunks,
        options.min_gain,
    )
    flat = all(v.holdout_rms_nt >= base.rms_nt * (1.0 - options.min_gain) for v in single.values())
    if not selected and flat:
        # Nothing moves the held-out residual: look for an effect the calibration absorbed whole.
        absorbed = _absorbed_by_calibration(data, sel.designs, base.rms_nt, robust=options.robust)
        if absorbed is not None and absorbed.name not in excluded:
            selected.append(absorbed.name)
            step_scores.append(absorbed)
            effects = [absorbed] + [e for e in effects if e.name != absorbed.name]
            confidence = None  # judged by a split fit, not by the held-out chunks
    # What the selected effects leave (e.g. a storm's auroral part once the ring current is in).
    nothing_selected = not selected
    effects, named_regionally = _named_regionally(
        data, candidates, split, final.residual_nt, selected, effects, len(step_scores)
    )
    if named_regionally and nothing_selected:
        confidence = None  # the verdict is a regional test's, not the held-out chunks'
    report_base, report_final, final_names = _report_models(
        data, split, final, chosen_blocks, named_regionally, options, [c.name for c in chosen]
    )
    splits = split_fit_tests(data, robust=options.robust) if options.split_tests else []
    return Attribution(
        baseline_rms_nt=report_base.rms_nt,
        baseline_train_rms_nt=norm_rms_nt(report_base.residual_nt[split.report_train]),
        verdict=selected[0] if selected else "none",
        effects=effects,
        selected=selected,
        final_rms_nt=report_final.rms_nt,
        train=split.report_train,
        holdout=split.report_holdout,
        baseline_residual_nt=report_base.residual_nt,
        final_residual_nt=report_final.residual_nt,
        split_fits=splits,
        fits={"baseline": report_base.fit, "final": report_final.fit},
        verdict_confidence=confidence,
        implausible=implausible,
        has_prior=data.calibration_prior is not None,
        span_s=float(data.t_utc_s[-1] - data.t_utc_s[0]),
        dropped=[n for n in stepwise.dropped if n not in excluded],
        fit_mask=None if fit_mask is None else np.asarray(fit_mask, dtype=bool),
        final_block_names=final_names,
        **_beside_final(data, split.train, stepwise, chosen),
    )


#: The closest candidates of the selection's last step (least held-out residual there) whose
#: containment in the chosen effects' model is measured (:func:`_beside_final`): those the gap
#: section names (:func:`orbitcal.diagnose.gap.gap_section`).
CLOSEST_CANDIDATES = 3


def _beside_final(
    data: DiagnosisData, train: BoolArray, stepwise: Stepwise, chosen: Sequence[Candidate]
) -> dict[str, Any]:
    """:attr:`Attribution.beside_final` and ``beside_final_of`` from the selection's last step
    (:attr:`Stepwise.last_step`), when it was beside the effects finally chosen; for the
    :data:`CLOSEST_CANDIDATES` that leave the least held-out residual there, the share of their
    single fit's field the chosen effects take up beyond the calibration (``contained``,
    :func:`contained_fraction`; None for the others)."""
    names = [c.name for c in chosen]
    if not names or sorted(stepwise.last_step_beside) != sorted(names):
        return {}
    step = stepwise.last_step
    closest = sorted(step, key=lambda n: step[n]["holdout_rms_nt"])[:CLOSEST_CANDIDATES]
    blocks = [c.block for c in chosen]
    out = {name: {**v, "contained": None} for name, v in step.items()}
    for name in closest:
        single = stepwise.single.get(name)
        if single is not None and single.fit.blocks:
            f = single.fit.effect_nt(len(single.fit.blocks) - 1)
            out[name]["contained"] = contained_fraction(data, train, blocks, f)
    return {"beside_final": out, "beside_final_of": names}
