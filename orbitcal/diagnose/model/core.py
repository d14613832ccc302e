"""The model core's driver: noise model, one whitened Gram matrix, the posterior over models,
one confirmation (``docs/design.md``, "The model core").

::

    training span ──encompassing fit──> residual ──> noise model per axis (BIC)
                  ──whitened Gram──> evidence of every model of <= 3 effects ──> posterior
    chosen model (inclusion >= cut-off), fitted on the training span
    final block (never seen above) ──> confirmation (Clark-West, Newey-West variance)

The driver names no effect: the catalogue gives each candidate's columns and prior.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.blocked import estimation_samples
from orbitcal.diagnose.columns import JoinedColumns
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.design import DesignBlock
from orbitcal.diagnose.effects import CATALOGUE, Effect
from orbitcal.diagnose.model.confirm import (
    BaseUncertainty,
    Confirmation,
    confirm,
    whitened_rows,
)
from orbitcal.diagnose.model.crossval import CrossValidation, cross_validated, orbital_period_s
from orbitcal.diagnose.model.evidence import (
    Augmented,
    Posterior,
    Projected,
    augment,
    averaged,
    log_evidence,
    log_model_prior,
    log_sum_exp,
    model_evidence,
    posterior,
    project,
)
from orbitcal.diagnose.model.gram import (
    Form,
    Gram,
    apply_model,
    design_rows,
    group_prior,
    whitened_gram,
    whitened_grams,
)
from orbitcal.diagnose.model.noise_model import (
    AxisNoise,
    fit_noise,
    forecast_noise,
    noise_skip,
    run_starts,
)
from orbitcal.diagnose.model.within_event import judged_by_events
from orbitcal.diagnose.options import ModelOptions

__all__ = ["ModelDiagnosis", "candidate_forms", "model_diagnosis", "run_starts"]

IntArray = np.ndarray

#: A noise model of unit white noise (the first, encompassing fit's).
_UNIT = AxisNoise("ar", np.zeros(0), 1.0, float("nan"))


@dataclass(frozen=True)
class ModelDiagnosis:
    """What the model core found.

    Attributes
    ----------
    posterior : Posterior
        Over every model of at most ``max_effects`` candidates.
    chosen : tuple of str
        The effects of inclusion probability at least the options' cut-off that also predict
        the training span's left-out orbits (``crossval``), most probable first.
    confirmation : Confirmation
        The chosen model against the calibration alone on the final block.
    noise : tuple of AxisNoise
        The noise model per sensor axis.
    absorbed : dict of str to float
        Per candidate, the share of its prior's field the calibration's 12 parameters reproduce.
    params : dict of str to dict
        Per candidate, its parameters' posterior mean (in the chosen model, else alone).
    forms : dict of str to str
        Per candidate, the form its evidence preferred (its design block's ``variant``).
    noise_weights : tuple of float
        Posterior weights of the noise models tried (of the calibration's residual, of the
        encompassing model's); ``noise`` is the heavier.
    crossval : CrossValidation
        The posterior's choice checked on orbit-long folds of the training span (``chosen`` is
        what it kept).
    effect_confirmations : dict of str to Confirmation
        With two or more chosen effects, per chosen effect the chosen model against the chosen
        model without it (both fitted on the training span) on the same final block: whether
        that effect, beside the others, forecasts the block better.
    beside : tuple of str
        Effects of the posterior's choice whose amplitudes change from event to event (an
        :attr:`~orbitcal.diagnose.effects.Effect.event_design`): fitted on the training span
        with the chosen model, never part of its forecast (they forecast no new event).
    event_probability : dict of str to float
        Per effect with an event design and events in the training span, its probability from
        its events' own amplitudes there (:mod:`orbitcal.diagnose.model.within_event`): its
        ``probability``, in place of the posterior's (of one set of amplitudes for every event).
    event_confirmations : dict of str to Confirmation
        Per such effect of probability at least the cut-off and with events in the final block,
        its within-event confirmation there, on what the forecast confirmation leaves.
    """

    posterior: Posterior
    chosen: tuple[str, ...]
    confirmation: Confirmation
    noise: tuple[AxisNoise, ...]
    absorbed: dict[str, float] = field(default_factory=dict)
    params: dict[str, dict[str, float]] = field(default_factory=dict)
    forms: dict[str, str] = field(default_factory=dict)
    noise_weights: tuple[float, ...] = ()
    crossval: CrossValidation = field(default_factory=lambda: CrossValidation(0))
    effect_confirmations: dict[str, Confirmation] = field(default_factory=dict)
    beside: tuple[str, ...] = ()
    event_probability: dict[str, float] = field(default_factory=dict)
    event_confirmations: dict[str, Confirmation] = field(default_factory=dict)

    def inclusion(self) -> dict[str, float]:
        """Posterior inclusion probability per candidate (an effect with an event design: from
        its events, :attr:`event_probability`)."""
        return {**self.posterior.inclusion(), **self.event_probability}

    def probability(self, effect: str) -> float:
        """Posterior probability that ``effect`` is present (0 for a candidate without witness
        in the data, and for ``"none"`` the probability that no effect is: no other effect, by
        the posterior, and none of those judged by their events, taken as independent)."""
        if effect == "none":
            events = self.event_probability
            post = self.posterior
            apart = {post.effects.index(e) for e in events if e in post.effects}
            p = sum(pr for m, pr in zip(post.models, post.prob, strict=True) if set(m) <= apart)
            for q in events.values():
                p *= 1.0 - q
            return float(p)
        return self.inclusion().get(effect, 0.0)


def _fill_sd(block: DesignBlock, sd: FloatArray, data: DiagnosisData) -> FloatArray:
    """Prior widths without a finite range: the width that makes the column's field 100 nT."""
    if np.all(np.isfinite(sd)):
        return sd
    from orbitcal.diagnose.model.gram import UNBOUNDED_FIELD_NT

    g = block.rows(slice(0, data.n, max(1, data.n // 2000)))
    rms = np.sqrt(np.mean(g**2, axis=(0, 1)))
    return np.where(np.isfinite(sd), sd, UNBOUNDED_FIELD_NT / np.maximum(rms, 1e-12))


def with_imperfect(block: DesignBlock, extra: DesignBlock | None) -> DesignBlock:
    """``block`` with an effect's imperfect-model columns ``extra`` after its own (and so every
    form its refinement makes); ``block`` itself without them."""
    if extra is None:
        return block
    refine = block.refine

    def refined() -> list[DesignBlock]:
        assert refine is not None
        return [with_imperfect(b, extra) for b in refine()]

    return dataclasses.replace(
        block,
        source=JoinedColumns(block.n, [block.rows, extra.rows], [block.width, extra.width]),
        names=[*block.names, *extra.names],
        alternatives=(),
        refine=None if refine is None else refined,
    )


def candidate_forms(
    data: DiagnosisData,
    train: BoolArray,
    options: ModelOptions,
    catalogue: Sequence[Effect] = CATALOGUE,
) -> list[Form]:
    """Every form of every candidate whose witness is in the data, with its columns and prior
    (each with its effect's imperfect-model columns, :attr:`Effect.imperfect`)."""
    forms: list[Form] = []
    col = 0
    for eff in catalogue:
        block = eff.design(data, train)
        own = [] if block is None else [block, *block.alternatives]
        if block is not None and block.other_sizes is not None:
            own += block.other_sizes()
        further = eff.further_design(data, train)
        if further is not None and further.all_finite():
            own.append(further)
        if not own or not own[0].all_finite():  # as the rules engine asks; a form with
            continue  # non-finite columns among the alternatives loses the choice (_best_forms)
        extra = eff.imperfect(data, train) if eff.imperfect is not None else None
        if extra is not None and not extra.all_finite():
            extra = None
        blocks = [with_imperfect(b, extra) for b in own]
        n_forms = sum(b.forms_searched for b in blocks)
        for b in blocks:
            mean, sd = group_prior(b, options.prior_sd_fraction)
            sd = _fill_sd(b, sd, data)
            forms.append(Form(eff.name, b, slice(col, col + b.width), mean, sd, n_forms))
            col += b.width
    return forms


def _theta_full(forms: Sequence[Form], chosen: Sequence[Form], theta: FloatArray) -> FloatArray:
    """The model's parameters placed in the Gram's effect columns (zero elsewhere)."""
    width = max((f.cols.stop for f in forms), default=0)
    out = np.zeros(width)
    k = 0
    for f in chosen:
        out[f.cols] = theta[k : k + f.block.width]
        k += f.block.width
    return out


def _beta(
    proj: Projected, gram_ce: FloatArray, gram_cy: FloatArray, theta: FloatArray
) -> FloatArray:
    """The calibration's parameters given the effects' (generalised least squares)."""
    return np.asarray(proj.cc_pinv @ (gram_cy - gram_ce @ theta))


#: Prior standard deviation of each calibration coefficient around its least-squares value [nT]
#: (a matrix element times FIELD_SCALE_NT, or an offset): 5 % of the field, wide enough that
#: it decides nothing the data tell; proper, so that noise models compare (``evidence``).
CAL_PRIOR_SD_NT = 2500.0


def _compact(forms: Sequence[Form]) -> list[Form]:
    """``forms`` with their columns renumbered side by side (a Gram matrix of these alone)."""
    out, col = [], 0
    for f in forms:
        out.append(dataclasses.replace(f, cols=slice(col, col + f.block.width)))
        col += f.block.width
    return out


def _refined_forms(
    data: DiagnosisData,
    index: IntArray,
    starts: IntArray,
    forms: Sequence[Form],
    options: ModelOptions,
) -> tuple[list[Form], list[Form], FloatArray]:
    """``forms`` with a time searched where an effect's design block offers a refinement (a
    drift's step time, a storm's minimum: a grid of times, then halving): the form the search
    ends on replaces the grid's forms (the effect's forms without a refinement, a trend, stay),
    and every form of that effect is paid for by the number of forms tried (``n_forms``, the
    Bonferroni bound over the search). Also each effect's best form (columns side by side as
    in the forms returned; the searched one where there is a search) and the calibration's
    least-squares value.

    Each effect's best form is chosen alone (by evidence under unit noise), and the other
    effects' best forms are the search's company: the time is searched **beside them**
    (:func:`_searched_beside`): searched alone, a step was placed where it best took up the
    other effects' fields, and the misplaced drift forecast worse than none. Without the
    refinement the model core chose among the grid's forms only, and a step between two grid
    times left a box taken as noise (``docs/design.md`` has the worlds and figures)."""
    unit = (_UNIT,) * 3
    apart = whitened_grams(data, index, starts, forms, [unit], forms_apart=True)[0]
    width = max((f.cols.stop for f in forms), default=0)
    cal_mean = _beta(project(apart), apart.ce, apart.cy, np.zeros(width))
    aug = _augmented(apart, cal_mean)
    alone = _best_forms(aug, forms)
    out = list(forms)
    bests = []
    for best in alone:
        grid = [f for f in forms if f.effect == best.effect and f.block.refine is not None]
        if not grid:
            bests.append(best)
            continue
        others = [b for b in alone if b.effect != best.effect]
        current, tried = _searched_beside(data, (index, starts), cal_mean, grid, others, options)
        n_forms = best.n_forms + tried
        # the search's form in place of the grid it searched; the effect's other forms stay
        out = [
            dataclasses.replace(f, n_forms=n_forms) if f.effect == best.effect else f
            for f in out
            if f.effect != best.effect or f.block.refine is None
        ]
        out.append(dataclasses.replace(current, n_forms=n_forms))
        # the effect's best form alone: the search's, or one of the forms it did not search
        plain = [f for f in forms if f.effect == best.effect and f.block.refine is None]
        (current_alone,) = _compact([current])
        searched = whitened_grams(data, index, starts, [current_alone], [unit])[0]
        alone_ev = _evidence_or_inf(_augmented(searched, cal_mean), current_alone)
        rival_ev, rival = max(
            ((_evidence_or_inf(aug, f), f) for f in plain), key=lambda p: p[0], default=(0.0, None)
        )
        if rival is not None and rival_ev > alone_ev:
            bests.append(next(f for f in out if f.block is rival.block))
        else:
            bests.append(out[-1])
    at = [next(j for j, f in enumerate(out) if f is b) for b in bests]
    out = _compact(out)
    return out, [out[j] for j in at], cal_mean


def _searched_beside(
    data: DiagnosisData,
    rows: tuple[IntArray, IntArray],
    cal_mean: FloatArray,
    grid: Sequence[Form],
    others: Sequence[Form],
    options: ModelOptions,
) -> tuple[Form, int]:
    """One effect's form of greatest evidence (under unit noise) beside the ``others`` (the
    other effects' best forms), and the number of refinement forms tried. The rows are ``rows``
    (the samples and their run starts).

    A form's evidence is summed over the models the posterior weighs that hold it: the form
    with none, one or more of the others (at most ``max_effects`` effects), each at its prior
    (:func:`~orbitcal.diagnose.model.evidence.log_model_prior`) and paid for by their forms'
    number. Beside all the others at once, an absent effect's flexible form (three sinusoids
    of an attitude error and its drift) took up a step that it then stood in for, and the step
    was placed where it fitted what they left (``docs/design.md``).

    The search starts from every local maximum of the evidence along the ``grid`` (in its
    order: the grid's times) and follows each by its refinements, the best of each in turn,
    until none is offered. A step's evidence is a narrow peak at its time: a grid time half a
    spacing away leaves a box of the step's height, and the grid's best can sit on a lesser
    peak (``docs/design.md``)."""
    index, starts = rows
    others = _compact(others)
    base = others[-1].cols.stop if others else 0

    def scored(candidates: Sequence[Form]) -> FloatArray:
        placed, col = [], base
        for c in candidates:
            placed.append(dataclasses.replace(c, cols=slice(col, col + c.block.width)))
            col += c.block.width
        gram = whitened_grams(data, index, starts, [*others, *placed], [(_UNIT,) * 3])[0]
        aug = _augmented(gram, cal_mean)
        evidence = np.full(len(placed), -np.inf)
        for k, c in enumerate(placed):
            terms = [_model_evidence_or_inf(aug, [*company, c]) + paid for company, paid in models]
            evidence[k] = log_sum_exp(terms)
        return evidence

    n_catalogue = len(CATALOGUE)
    models = [
        (
            company,
            log_model_prior(len(company) + 1, options.expected_effects, n_catalogue)
            - sum(math.log(f.n_forms) for f in company),
        )
        for size in range(min(options.max_effects - 1, len(others)) + 1)
        for company in itertools.combinations(others, size)
    ]

    def refined(form: Form) -> list[Form]:
        out = []
        for b in form.block.refine() if form.block.refine is not None else []:
            mean, sd = group_prior(b, options.prior_sd_fraction)
            out.append(Form(form.effect, b, slice(0, b.width), mean, _fill_sd(b, sd, data), 0))
        return out

    ev = scored(grid)
    padded = np.r_[-np.inf, ev, -np.inf]
    peaks = np.flatnonzero((ev >= padded[:-2]) & (ev >= padded[2:]) & np.isfinite(ev))
    paths = [(float(ev[k]), grid[int(k)]) for k in (peaks if peaks.size else [np.argmax(ev)])]
    done, tried = [p for p in paths if p[1].block.refine is None], 0
    paths = [p for p in paths if p[1].block.refine is not None]
    while paths:
        groups = [refined(form) for _, form in paths]
        tried += sum(len(g) for g in groups)
        ev = scored([f for g in groups for f in g])
        paths, k = [], 0
        for g in groups:
            j = k + int(np.argmax(ev[k : k + len(g)]))
            best = (float(ev[j]), g[j - k])
            (paths if best[1].block.refine is not None else done).append(best)
            k += len(g)
    return max(done, key=lambda p: p[0])[1], tried


def _model_evidence_or_inf(aug: Augmented, forms: Sequence[Form]) -> float:
    """The evidence of the model of ``forms``; ``-inf`` for one that cannot be scored
    (non-finite columns)."""
    try:
        ev = model_evidence(aug, forms)[0]
    except np.linalg.LinAlgError:
        return -np.inf
    return float(ev) if np.isfinite(ev) else -np.inf


def _evidence_or_inf(aug: Augmented, form: Form) -> float:
    """A form's evidence alone (:func:`_model_evidence_or_inf`)."""
    return _model_evidence_or_inf(aug, [form])


def _noise_candidates(
    data: DiagnosisData,
    index: IntArray,
    starts: IntArray,
    forms: Sequence[Form],
    best: Sequence[Form],
    beta_ls: FloatArray,
    max_order: int,
) -> list[tuple[AxisNoise, ...]]:
    """Two noise models of the training residual -- of the calibration alone (at its
    least-squares value ``beta_ls``), and of the encompassing model (every candidate in its
    ``best`` form under unit noise, at its posterior mean: what no candidate explains).

    Each candidate's *best* form, not its first: a drift's first form is a trend, and a drift
    with a step (our simulator's) left the step in the encompassing residual, whose noise model
    then became a random-walk offset as the calibration's did, and the drift, whitened away as
    noise, got probability 0 with 18 nT left on the final block."""
    zero = np.zeros(max((f.cols.stop for f in forms), default=0))
    out = [fit_noise(apply_model(data, index, forms, beta_ls, zero), starts, max_order=max_order)]
    if best:
        compact = _compact(best)
        gram = whitened_gram(data, index, starts, compact, (_UNIT,) * 3)
        proj = project(gram)
        mean = np.concatenate([f.prior_mean for f in compact])
        sd = np.concatenate([f.prior_sd for f in compact])
        _, theta = log_evidence(proj, np.arange(mean.size, dtype=np.intp), mean, sd)
        beta = _beta(proj, gram.ce, gram.cy, theta)
        residual = apply_model(data, index, compact, beta, theta)
        out.append(fit_noise(residual, starts, max_order=max_order))
    return out


def _augmented(gram: Gram, cal_mean: FloatArray) -> Augmented:
    """The Gram matrix with the calibration's prior (:data:`CAL_PRIOR_SD_NT`)."""
    return augment(gram, cal_mean, np.full(12, CAL_PRIOR_SD_NT), gram.log_scale)


def _best_forms(aug: Augmented, forms: Sequence[Form]) -> list[Form]:
    """Per effect, the form of greatest evidence alone (its choice paid for by ``n_forms``)."""
    best: dict[str, tuple[float, Form]] = {}
    for f in forms:
        ev = _evidence_or_inf(aug, f)
        if f.effect not in best or ev > best[f.effect][0]:
            best[f.effect] = (ev, f)
    return [best[e][1] for e in dict.fromkeys(f.effect for f in forms)]


def _absorbed(proj: Projected, forms: Sequence[Form]) -> dict[str, float]:
    """Share of each form's prior-scaled column energy the calibration's columns take."""
    out = {}
    for f in forms:
        ix = np.arange(f.cols.start, f.cols.stop)
        s2 = f.prior_sd**2
        raw = float(np.sum(s2 * proj.g_raw_diag[ix]))
        kept = float(np.sum(s2 * np.diag(proj.g)[ix]))
        out[f.effect] = float(np.clip(1.0 - kept / raw, 0.0, 1.0)) if raw > 0.0 else 1.0
    return out


@dataclass(frozen=True)
class _Fitted:
    """The posterior under one noise model."""

    noise: tuple[AxisNoise, ...]
    gram: Gram
    best: list[Form]
    post: Posterior


def _under(
    forms: Sequence[Form],
    gram: Gram,
    noise: tuple[AxisNoise, ...],
    cal_mean: FloatArray,
    options: ModelOptions,
    best: list[Form],
) -> _Fitted:
    """The posterior under one noise model of its effects' ``best`` forms, from its Gram
    matrix (over ``forms``)."""
    aug = _augmented(gram, cal_mean)
    post = posterior(
        aug,
        best,
        expected_effects=options.expected_effects,
        max_effects=options.max_effects,
        n_catalogue=len(CATALOGUE),
    )
    return _Fitted(noise, gram, best, post)


@dataclass(frozen=True)
class _Stage:
    """The selection's products on the training span (:func:`_selection_stage`)."""

    forms: list[Form]
    index: IntArray
    step: int
    starts: IntArray
    skip: int
    cal_mean: FloatArray
    fits: list[_Fitted]
    post: Posterior
    weights: FloatArray
    fit: _Fitted


def _selection_stage(
    data: DiagnosisData,
    train: BoolArray,
    options: ModelOptions,
    forms: Sequence[Form] | None,
) -> _Stage:
    """Forms, noise models and the posterior over models, from the training span only."""
    forms = list(candidate_forms(data, train, options) if forms is None else forms)
    index = estimation_samples(train)
    step = int(np.median(np.diff(index))) if index.size > 1 else 1
    starts = run_starts(data, index, step)
    forms, best_unit, cal_mean = _refined_forms(data, index, starts, forms, options)
    noises = _noise_candidates(
        data, index, starts, forms, best_unit, cal_mean, options.noise_max_order
    )
    skip = noise_skip(options.noise_max_order)
    # each effect's form chosen under each noise model from the forms' own products, then the
    # whole Gram matrix of the chosen forms alone (the products between forms of one effect,
    # never in one model, are not made)
    apart = whitened_grams(data, index, starts, forms, noises, skip=skip, forms_apart=True)
    bests = [_best_forms(_augmented(g, cal_mean), forms) for g in apart]
    used = [f for f in forms if any(f is b for best in bests for b in best)]
    forms = _compact(used)
    bests = [[forms[next(j for j, u in enumerate(used) if u is b)] for b in best] for best in bests]
    grams = whitened_grams(data, index, starts, forms, noises, skip=skip)
    fits = [
        _under(forms, g, n, cal_mean, options, best)
        for g, n, best in zip(grams, noises, bests, strict=True)
    ]
    post, weights = averaged([f.post for f in fits])
    fit = fits[int(np.argmax(weights))]
    return _Stage(forms, index, step, starts, skip, cal_mean, fits, post, weights, fit)


def _chosen(
    data: DiagnosisData,
    train: BoolArray,
    st: _Stage,
    by_effect: dict[str, Form],
    options: ModelOptions,
    confirm_model: Sequence[str] | None,
) -> tuple[tuple[str, ...], tuple[str, ...], CrossValidation]:
    """The posterior's choice kept by the cross-validation, the effects fitted beside it, and
    the cross-validation. Effects whose amplitudes change from event to event are fitted with
    the chosen model but never forecast (nor cross-validated across orbits): their own test is
    within the events of the final block (:mod:`~orbitcal.diagnose.model.within_event`)."""
    chosen = st.post.median_model(options.selection_probability)
    event_local = {e.name for e in CATALOGUE if e.event_design is not None}
    beside = tuple(e for e in chosen if e in event_local)
    chosen = tuple(e for e in chosen if e not in event_local)
    if confirm_model is not None:
        return tuple(confirm_model), (), CrossValidation(0, kept=tuple(confirm_model))
    if not chosen:
        return chosen, beside, CrossValidation(0, kept=chosen)
    crossval = cross_validated(
        data,
        train,
        _compact([by_effect[e] for e in chosen]),
        st.fit.noise,
        skip=st.skip,
        cal_mean=st.cal_mean,
        cal_sd=np.full(12, CAL_PRIOR_SD_NT),
        outside=lambda index: outside_events(data, index, beside),
    )
    return crossval.kept, beside, crossval


def outside_events(data: DiagnosisData, index: IntArray, effects: Sequence[str]) -> BoolArray:
    """Per position of the samples ``index``, whether it lies outside every event of the
    ``effects`` with an event design. Such an effect's amplitudes change from event to event:
    fitted on some samples it forecasts nothing of another event, so its field in an event is
    an error of every forecast, with or without the chosen effects. The forecast comparisons
    (the cross-validation's folds, the confirmation) are made on the samples outside them; the
    events' own test is within them (:mod:`~orbitcal.diagnose.model.within_event`)."""
    keep = np.ones(np.asarray(index).size, dtype=bool)
    for effect in CATALOGUE:
        if effect.name in effects and effect.event_design is not None:
            for event in effect.event_design.events(data, np.asarray(index)):
                keep[event.rows] = False
    return keep


def model_diagnosis(
    data: DiagnosisData,
    train: BoolArray,
    holdout: BoolArray,
    options: ModelOptions = ModelOptions(),
    forms: Sequence[Form] | None = None,
    confirm_model: Sequence[str] | None = None,
) -> ModelDiagnosis:
    """The model core on ``data``: selection on ``train`` only, one confirmation on ``holdout``.

    ``forms`` (from :func:`candidate_forms` on the same data and training span) may be given
    to reuse the design between calls on the same world. ``confirm_model`` (candidates' names,
    at most ``max_effects``) confirms that model instead of the chosen one, and tests every
    effect with an event design whatever its probability: for measuring the confirmation's
    size on null worlds (``benchmarks/diagnose_model.py``).
    """
    st = _selection_stage(data, train, options, forms)
    forms, index, step, starts = st.forms, st.index, st.step, st.starts
    post, fit, fits = st.post, st.fit, st.fits
    by_effect = {f.effect: f for f in fit.best}
    chosen, beside, crossval = _chosen(data, train, st, by_effect, options, confirm_model)
    h_index = np.flatnonzero(holdout)
    h_starts = run_starts(data, h_index, 1)

    def fitted(names: Sequence[str]) -> tuple[FloatArray, list[Form], FloatArray]:
        """The model ``names`` (with ``beside``) fitted on the training span: its parameters
        (calibration first), its forms, and its effect parameters placed in the Gram's
        columns."""
        names = (*names, *beside) if names else ()
        params = post.thetas[post.models.index(tuple(sorted(post.effects.index(e) for e in names)))]
        model_forms = [by_effect[e] for e in sorted(names, key=post.effects.index)]
        return params, model_forms, _theta_full(forms, model_forms, params[12:])

    params, chosen_forms, chosen_full = fitted(chosen)
    # whitened by the noise model of the chosen model's own training residual: what is left
    # when the chosen effects are right (and, when they are not there, about the calibration's
    # residual). The calibration's residual holds any effect present, which makes a slow one
    # (a drift) look like a random-walk offset whose whitening hides the level error the effect
    # removes: the drift of our simulator forecast 6.1 -> 2.0 nT at p 0.81.
    trained_chosen = apply_model(data, index, forms, params[:12], chosen_full)
    test_noise = (
        fit_noise(trained_chosen, starts, max_order=options.noise_max_order)
        if chosen
        else fits[0].noise
    )

    def forecast_error(names: Sequence[str]) -> FloatArray:
        """The final block's error of the model ``names`` fitted on the training span (the
        effects ``beside`` it not forecast), its noise forecast from the training residual
        (:func:`forecast_noise`) taken off: a persistent noise model leaves the offsets'
        level to the noise, which carries the level the training span ended at."""
        params, _, full = fitted(names)
        same = tuple(names) == tuple(chosen)
        trained = trained_chosen if same else apply_model(data, index, forms, params[:12], full)
        for e in beside:
            full[by_effect[e].cols] = 0.0
        error = apply_model(data, h_index, forms, params[:12], full)
        return error - forecast_noise(test_noise, trained, index, step, h_index)

    e_model = forecast_error(chosen)
    e_base = forecast_error(()) if chosen else e_model
    # the forecasts are compared outside the events of the effects fitted beside them (on the
    # whole block when fewer than a few samples are outside them: a block all at high latitude)
    quiet = outside_events(data, h_index, beside)
    if np.sum(quiet) < 3:
        quiet[:] = True
    q_index = h_index[quiet]
    q_starts = run_starts(data, q_index, 1)
    base = _base_uncertainty(
        data, st, [by_effect[e] for e in chosen], test_noise, (q_index, q_starts)
    )
    each = (
        {
            e: confirm(
                forecast_error([c for c in chosen if c != e])[quiet],
                e_model[quiet],
                test_noise,
                q_starts,
                base=base([c for c in chosen if c != e]),
            )
            for e in chosen
        }
        if len(chosen) > 1
        else {}
    )
    orbit = _orbit_samples(data, h_index)
    confirmation = confirm(
        e_base[quiet], e_model[quiet], test_noise, q_starts, orbit, base=base(())
    )
    # what the forecast confirmation names leaves; the events' own test is made on it
    left = e_model if chosen and confirmation.passes(options.confirmation_level) else e_base
    # the chosen model's training residual with the events' own field left in it
    for e in beside:
        chosen_full[by_effect[e].cols] = 0.0
    trained_apart = (
        apply_model(data, index, forms, params[:12], chosen_full) if beside else trained_chosen
    )
    events = judged_by_events(
        data,
        (index, starts, step, trained_apart),
        (h_index, h_starts, left, orbit),
        CATALOGUE,
        options,
        force=confirm_model is not None,
    )
    return ModelDiagnosis(
        posterior=post,
        chosen=chosen,
        confirmation=confirmation,
        effect_confirmations=each,
        beside=beside,
        event_probability=events.probability,
        event_confirmations=events.confirmations,
        noise=fit.noise,
        absorbed=_absorbed(project(fit.gram), fit.best),
        params=_params(post, fit.best, chosen_forms, params[12:]),
        forms={f.effect: f.block.variant for f in fit.best},
        noise_weights=tuple(float(w) for w in st.weights),
        crossval=crossval,
    )


def _base_uncertainty(
    data: DiagnosisData,
    st: _Stage,
    chosen: Sequence[Form],
    noise: tuple[AxisNoise, ...],
    final: tuple[IntArray, IntArray],
) -> Callable[[Sequence[str]], BaseUncertainty | None]:
    """Per base model of the confirmation (the calibration with some of the ``chosen`` forms),
    its columns on the final block (``final``: its samples and run starts), whitened once by the
    test's noise model, and its parameters' posterior covariance on the training span under
    that noise model (:func:`~orbitcal.diagnose.model.confirm.predictive_rows`): one Gram matrix
    of the calibration and the chosen forms, each base model's block of it inverted with its
    prior. None without a chosen form (no test is made)."""
    if not chosen:
        return lambda names: None
    forms = _compact(chosen)
    aug = _augmented(
        whitened_gram(data, st.index, st.starts, forms, noise, skip=st.skip), st.cal_mean
    )
    h_index, h_starts = final
    whitened = whitened_rows(design_rows(data, h_index, forms), noise, h_starts)

    def base(names: Sequence[str]) -> BaseUncertainty:
        used = [f for f in forms if f.effect in names]
        cols = np.r_[np.arange(12), *(12 + np.arange(f.cols.start, f.cols.stop) for f in used)]
        sd = np.concatenate([aug.cal_sd, *(f.prior_sd for f in used)])
        precision = aug.g[np.ix_(cols, cols)] + np.diag(1.0 / sd**2)
        return BaseUncertainty(whitened[:, :, cols], np.linalg.pinv(precision, hermitian=True))

    return base


def _orbit_samples(data: DiagnosisData, index: IntArray) -> int:
    """Samples of one orbit at the cadence of the samples ``index`` (the shrink's bootstrap
    blocks, :func:`~orbitcal.diagnose.model.confirm.shrink_interval`)."""
    if index.size < 2:
        return 0
    step_s = float(np.median(np.diff(data.t_utc_s[index])))
    return int(np.ceil(orbital_period_s(data) / step_s)) if step_s > 0.0 else 0


def _params(
    post: Posterior, best: Sequence[Form], chosen: Sequence[Form], theta: FloatArray
) -> dict[str, dict[str, float]]:
    """Posterior means: in the chosen model for its effects, alone for the others."""
    out: dict[str, dict[str, float]] = {}
    k = 0
    for f in chosen:
        out[f.effect] = dict(zip(f.block.names, theta[k : k + f.block.width].tolist(), strict=True))
        k += f.block.width
    for i, f in enumerate(best):
        if f.effect not in out:
            alone = post.thetas[post.models.index((i,))][12:]
            out[f.effect] = dict(zip(f.block.names, alone.tolist(), strict=True))
    return out
