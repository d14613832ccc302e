"""The diagnosis's one entry: telemetry + orbit -> :class:`~orbitcal.diagnose.result.Diagnosis`.

::

    telemetry, orbit ──diagnosis_data──> DiagnosisData ──diagnose_data──> Diagnosis
                        (prepare.py)                      │ learned crust (learned.py)
                                                          │ attribute (attribution/),
                                                          │   beside it the model core (model/)
                                                          │ where_analysis (where.py)
                                                          └ build_report (report.py) -> Report

:func:`diagnose` is what the CLI, the service, the notebook API and the benchmark call, with one
:class:`~orbitcal.diagnose.options.DiagnosisOptions` (every default lives there: reference field,
crustal model, learned model, prior widths, seed, BLAS threads). :func:`diagnose_data` is its
second half, on arrays already prepared (tests and benchmarks that build or alter them).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, nullcontext
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.diagnose.evidence import evidence
from orbitcal.diagnose.options import AttributionOptions, DiagnosisOptions
from orbitcal.diagnose.prepare import (
    CRUST_KNOT_SPACING_S,
    DEFAULT_CRUST_MODEL,
    diagnosis_data,
    rotation_itrs_to_body,
)
from orbitcal.diagnose.prior import CalibrationPrior, prior_from_document
from orbitcal.diagnose.result import Diagnosis, Report
from orbitcal.errors import NotEnoughDataError

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.arrays import BoolArray
    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.data import DiagnosisData
    from orbitcal.diagnose.honesty import Review
    from orbitcal.diagnose.model import ModelDiagnosis
    from orbitcal.orbit import Propagator
    from orbitcal.telemetry import Telemetry

__all__ = [
    "CRUST_KNOT_SPACING_S",
    "DEFAULT_CRUST_MODEL",
    "LEARNED_CRUST",
    "Diagnosis",
    "DiagnosisOptions",
    "Report",
    "diagnose",
    "diagnose_data",
    "diagnosis_data",
    "resolve_prior",
    "rotation_itrs_to_body",
]

#: Name of the crustal_field variant the seed-003 model stands for.
LEARNED_CRUST = "learned (seed 003)"


def resolve_prior(
    prior: CalibrationPrior | Mapping[str, Any] | None, options: DiagnosisOptions
) -> CalibrationPrior | None:
    """The prior on the 12 parameters: as given, or made from a calibration document (section
    4) with the widths of ``options``.

    Raises
    ------
    BadInputError
        A document without a usable linear part.
    """
    if prior is None or isinstance(prior, CalibrationPrior):
        return prior
    return prior_from_document(
        dict(prior),
        sigma_a=options.prior_sigma_matrix,
        sigma_o_nt=options.prior_sigma_offset_nt,
    )


def _threads(options: DiagnosisOptions) -> Any:
    from orbitcal.blas import one_blas_thread

    return one_blas_thread() if options.one_blas_thread else nullcontext()


def diagnose(
    telemetry: Telemetry,
    *,
    orbit: Propagator | None,
    options: DiagnosisOptions = DiagnosisOptions(),
    prior: CalibrationPrior | Mapping[str, Any] | None = None,
    rng: np.random.Generator | None = None,
) -> Diagnosis:
    """Diagnose the sim-to-real gap of a telemetry table (CONTRACT section 5).

    Parameters
    ----------
    telemetry : Telemetry
        Validated table with attitude quaternions; positions from the table or ``orbit``.
    orbit : Propagator or None
        The spacecraft's orbit (TLE/OMM through :class:`orbitcal.orbit.Orbit`); None when the
        table carries positions.
    options : DiagnosisOptions
        Everything else the diagnosis is asked with (defaults: IGRF-14, GCRS, LCS-1, the
        learned model, seed 0, one BLAS thread).
    prior : CalibrationPrior or dict, optional
        The calibration in service as a prior on the 12 parameters: a prior, or a section-4
        document (its widths from ``options``). Needed on short spans such as a storm pass.
    rng : numpy.random.Generator, optional
        Seeds the learned model's network initialisation (default: ``options.seed``).

    Returns
    -------
    Diagnosis
        ``report`` (section 5, :meth:`Report.to_json`), ``attribution`` and ``data``.

    Raises
    ------
    BadInputError
        No attitude quaternions, an unknown attitude frame, an unusable prior document.
    NotEnoughDataError
        Too short a span for held-out attribution.
    """
    from orbitcal.memory import trim_heap

    calibration_prior = resolve_prior(prior, options)
    with _threads(options):
        data = diagnosis_data(
            telemetry, orbit=orbit, options=options, calibration_prior=calibration_prior
        )
        trim_heap()  # the truth's intermediates are freed: return their pages
        return _run(data, options, rng, None)


def diagnose_data(
    data: DiagnosisData,
    *,
    options: DiagnosisOptions = DiagnosisOptions(),
    rng: np.random.Generator | None = None,
    fit_mask: BoolArray | None = None,
) -> Diagnosis:
    """The diagnosis of prepared arrays (:func:`diagnosis_data`): the second half of
    :func:`diagnose`.

    ``fit_mask`` further restricts the samples every fit may use (e.g. quiet magnetic latitudes
    of a storm pass); held-out scoring still uses every held-out sample. The options' data
    settings (field, frame, crustal and external models) were used when ``data`` was built.
    """
    with _threads(options):
        return _run(data, options, rng, fit_mask)


def _run(
    data: DiagnosisData,
    options: DiagnosisOptions,
    rng: np.random.Generator | None,
    fit_mask: BoolArray | None,
) -> Diagnosis:
    """Learned crust (without a crustal model), attribution, where-analysis, report.

    Without a crustal model (``data.b_crust_body_nt`` None) and with ``options.learned``, the
    seed-003 model is first fitted to the calibration residual of the training blocks; if its
    training-only cross-validation keeps a stage, its correction is the crustal_field candidate
    (``variant`` ``"learned (seed 003)"``), judged on the held-out blocks like any other.
    """
    from orbitcal.diagnose.report import build_report
    from orbitcal.diagnose.where import where_analysis

    rng = rng if rng is not None else np.random.default_rng(options.seed)
    options, fit_mask, chosen = _chosen_from_data(data, options, fit_mask)
    learned_result = None
    if options.learned and data.b_crust_body_nt is None:
        data, learned_result = _with_learned_crust(data, options, rng, fit_mask)
    with ExitStack() as stack:
        model = _model_core_started(data, options, fit_mask, stack)
        att, rv = _attribute_reviewed(data, options, fit_mask)
        where = where_analysis(data, att.baseline_residual_nt, holdout=att.holdout)
        where_final = (
            where_analysis(data, att.final_residual_nt, holdout=att.holdout)
            if att.selected
            else None
        )
        if options.learned and learned_result is None:
            learned_result = _learned_summary(data, att, rng)
        document = build_report(data, att, where, learned=learned_result, where_final=where_final)
        # Issue 25: the report's claims checked on the held-out data (orbitcal.diagnose.honesty):
        # possible residues, a fall-back when the final model is worse than the baseline, the
        # gap.
        from orbitcal.diagnose.honesty import reviewed
        from orbitcal.diagnose.honesty_report import review_report
        from orbitcal.diagnose.model import with_model_keys

        final_att = reviewed(data, att, rv)
        document["evidence"] = evidence(data, final_att)  # curves the HTML page draws
        document = review_report(document, data, att, chosen=chosen, rv=rv)
        document = with_model_keys(document, model(), options.model)
    return Diagnosis(report=Report.from_json(document), attribution=final_att, data=data)


def _model_core_started(
    data: DiagnosisData,
    options: DiagnosisOptions,
    fit_mask: BoolArray | None,
    stack: ExitStack,
) -> Callable[[], ModelDiagnosis]:
    """The model core's result (:mod:`orbitcal.diagnose.model`, on the rules engine's training
    span and final block: the numbers of the report's ``probability``, ``verdict_probability``,
    ``confirmation`` and ``model`` keys), to be asked for once the rules engine's report is
    built.

    The two engines read the same prepared data and share nothing they write but the catalogue's
    design blocks (:meth:`Effect.design`, kept per data set). With two or more selection
    workers (:attr:`AttributionOptions.workers`) on a machine of two or more cores, those
    blocks are built first, two at a time, the scanned ones first (the attitude error's period
    scan: 0.8-0.9 s on a day at 1 Hz, which both engines would otherwise make; beside it the
    others, the time offset's body rate the longest), and the model core then runs on a thread
    of its own, beside the rules engine. On the torquer day at 1 Hz of
    ``benchmarks/diagnose_timing.py`` (three pairs against the serial order, same report to the
    bit): median 0.91x the wall time, 1.07x the CPU time (both threads hold the interpreter for
    much of their work), 563-581 MB of peak memory against 506-546 (both engines' arrays alive
    at once); building the blocks two at a time rather than one after the other took a further
    0.904x of the wall over six pairs (twenty-fourth session, the timing page). Otherwise it
    runs when asked, after the rules engine, as before. The thread is joined when ``stack``
    closes; an error in it is raised when the result is asked for.
    """
    from orbitcal.diagnose.attribution.engine import training_split
    from orbitcal.diagnose.effects import CATALOGUE
    from orbitcal.diagnose.model import model_diagnosis

    def after() -> ModelDiagnosis:
        train, holdout = training_split(data, options.attribution, fit_mask)
        return model_diagnosis(data, train, holdout, options.model)

    if min(options.attribution.workers, os.cpu_count() or 1) < 2:
        return after
    try:
        train, holdout = training_split(data, options.attribution, fit_mask)
    except NotEnoughDataError:  # the rules engine says so, in its own words
        return after
    # the blocks two at a time, the scanned ones (the longest) first
    with ThreadPoolExecutor(2, thread_name_prefix="orbitcal-design") as builders:
        ordered = sorted(CATALOGUE, key=lambda eff: not eff.rescanned_beside_others)
        list(builders.map(lambda eff: eff.design(data, train), ordered))
    pool = stack.enter_context(ThreadPoolExecutor(1, thread_name_prefix="orbitcal-model-core"))
    return pool.submit(model_diagnosis, data, train, holdout, options.model).result


def _learned_summary(
    data: DiagnosisData, att: Attribution, rng: np.random.Generator
) -> dict[str, Any]:
    """The seed-003 model fitted to what the final model leaves on the training blocks, unless
    that is already the white noise (held-out RMS per component within
    :data:`~orbitcal.diagnose.learned.LEARNED_MIN_TIMES_NOISE` of the noise floor of
    :func:`~orbitcal.diagnose.gap.noise_floor_nt`): then there is no field for it to learn, and
    its fit (a quarter of a diagnosis's time on a day at 1 Hz) is not made."""
    from orbitcal.diagnose.gap import noise_ratio
    from orbitcal.diagnose.learned import (
        LEARNED_MIN_TIMES_NOISE,
        learned_field_error,
        not_fitted_summary,
    )

    sigma, rms_pc, times = noise_ratio(att.final_residual_nt, att.final_rms_nt, att.holdout)
    if np.isfinite(times) and times <= LEARNED_MIN_TIMES_NOISE:
        summary = not_fitted_summary(
            f"the final model's held-out residual ({rms_pc:.4g} nT per component) is at the "
            f"white-noise floor ({sigma:.4g} nT, {times:.2f}x; at most "
            f"{LEARNED_MIN_TIMES_NOISE:g}x): no field is left for a learned model to find"
        )
    else:
        summary = learned_field_error(
            data, att.final_residual_nt, train=att.train, holdout=att.holdout, rng=rng
        )
    summary["fitted_to"] = "the final model's residual on the training blocks"
    return summary


def _attribute_reviewed(
    data: DiagnosisData, options: DiagnosisOptions, fit_mask: BoolArray | None
) -> tuple[Attribution, Review]:
    """The attribution and its review (:func:`orbitcal.diagnose.honesty.review`), with a second
    look when the review withdrew a selected effect and left a gap.

    The selection chose each effect among the candidates that passed at its step; when the review
    then withdraws the chosen one (its gain came and went with a slow wander, its field is within
    the noise's wander, a possible residue, immaterial), the candidate next in line was never
    judged in its place (independent worlds 11500 no. 10 and 11600 no. 0: an attitude error that
    passed alone at p = 0.0015 and 0.0003 lost the first step to a Sun-driven field and a time
    offset the review then withdrew, and the report said "none" or named the currents alone with
    a gap of 6.8 x the noise). The selection is then run again without the withdrawn effects; its
    result, reviewed in turn, replaces the first when it keeps an effect the first did not (one
    the stepwise selection chose, not one named by its own regional test). The
    withdrawn effects keep their status and reason in the report.
    """
    from orbitcal.diagnose.attribution import attribute
    from orbitcal.diagnose.honesty import (
        OWN_TEST,
        review,
        second_look_exclusions,
        with_earlier,
    )

    att = attribute(data, options=options.attribution, fit_mask=fit_mask)
    rv = review(data, att)
    excluded, twin_of = second_look_exclusions(att, rv)
    if not excluded:
        return att, rv
    again = attribute(data, options=options.attribution, fit_mask=fit_mask, excluded=excluded)
    rv_again = review(data, again, excluded)
    new = set(rv_again.keep) - set(rv.keep) - _named_by_rotation(rv_again)
    # The second look is for a candidate the stepwise selection passed over: an effect named by
    # its own regional test on what the second selection leaves is no such candidate
    # (independent world 11700 no. 4: auroral currents of nothing injected, named beside none).
    if not new or new & OWN_TEST:
        return att, rv
    return again, with_earlier(rv_again, rv, excluded, twin_of)


def _named_by_rotation(rv: Review) -> set[str]:
    """The attitude error when the review named it by its own test, not the selection."""
    from orbitcal.diagnose.honesty import ATTITUDE

    return {ATTITUDE} if rv.rotation is not None and rv.rotation.named else set()


def _chosen_from_data(
    data: DiagnosisData, options: DiagnosisOptions, fit_mask: BoolArray | None
) -> tuple[DiagnosisOptions, BoolArray | None, list[str]]:
    """Options a short span needs, chosen from the data (:mod:`orbitcal.diagnose.span_options`):
    held-out blocks and quiet-latitude fitting; a value the caller set (a non-default
    ``holdout_blocks``, a ``fit_mask``) is kept. Returns the options, the fit mask and one
    sentence per choice for the report."""
    from orbitcal.diagnose.span_options import choose_options

    given: dict[str, Any] = {"n_blocks": options.attribution.n_blocks}
    if options.attribution.holdout_blocks != AttributionOptions().holdout_blocks:
        given["holdout_blocks"] = options.attribution.holdout_blocks
    if fit_mask is not None:
        given["fit_mask"] = fit_mask
    out, chosen = choose_options(data, given)
    attribution = dataclasses.replace(
        options.attribution,
        holdout_blocks=int(out.get("holdout_blocks", options.attribution.holdout_blocks)),
    )
    return dataclasses.replace(options, attribution=attribution), out.get("fit_mask"), chosen


def _with_learned_crust(
    data: DiagnosisData,
    options: DiagnosisOptions,
    rng: np.random.Generator,
    fit_mask: BoolArray | None,
) -> tuple[DiagnosisData, dict[str, Any] | None]:
    """The data with the seed-003 correction as crustal model, and the model's summary.

    ``(data, None)`` when the samples are too few for attribution (:func:`attribute` then says
    why); the summary with the data unchanged when the model keeps no stage.
    """
    from orbitcal.diagnose.attribution import fit_joint
    from orbitcal.diagnose.attribution.engine import training_split
    from orbitcal.diagnose.learned import learned_field_model

    try:
        train, holdout = training_split(data, options.attribution, fit_mask)
    except NotEnoughDataError:
        return data, None
    base = fit_joint(data, train)
    summary, correction = learned_field_model(
        data, data.b_raw_nt - base.predict_nt(data), train=train, holdout=holdout, rng=rng
    )
    summary["fitted_to"] = "the calibration-only residual of the training blocks"
    if summary["stage_chosen"] == "none":
        return data, summary
    summary["candidate"] = f"crustal_field ({LEARNED_CRUST})"
    replaced = dataclasses.replace(
        data, b_crust_body_nt=correction, b_crust_low_body_nt=None, crust_model=LEARNED_CRUST
    )
    return replaced, summary
