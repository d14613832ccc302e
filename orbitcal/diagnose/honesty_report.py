"""The report's claims checked against the held-out data: what :func:`orbitcal.diagnose.honesty.
review` decided, written into the report.

The review (:mod:`orbitcal.diagnose.honesty`) decides which effects stand; this module marks the
withdrawn ones with their status and reason, rewrites the ``final`` section and the verdict when
the selection changed, marks intervals that reach a physical bound (``bound_limited``), and adds
the ``gap``, ``separable`` and ``honesty`` sections.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.diagnose.confounding import confounding_words
from orbitcal.diagnose.effects import effect_param_range
from orbitcal.diagnose.extrapolation import extrapolation_words
from orbitcal.diagnose.gap import deciders, gap_section, verdict_status
from orbitcal.diagnose.honesty import (
    ATTITUDE,
    CORRELATED_ALPHA,
    LARGE_GAP_TIMES_NOISE,
    MATERIAL_GAIN,
    OVERSHADOW_RATIO,
    OWN_TEST,
    UNLIT_REASON,
    WEAK_CURRENTS_NT,
    Review,
    _fit_names,
    absorbed_candidates,
    inseparable_candidates,
    review,
)
from orbitcal.diagnose.wander import ACROSS_B, wander_reason
from orbitcal.metrics import rms_nt_from_norm

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.effects import DiagnosisData

__all__ = ["review_report"]


def _bound_limited(effect: dict[str, Any], age_days: float | None = None) -> dict[str, bool]:
    out: dict[str, bool] = {}
    for name, iv in (effect.get("param_intervals_90") or {}).items():
        if iv is None or len(iv) != 2 or iv[0] is None or iv[1] is None:
            continue
        rng = effect_param_range(str(effect.get("name")), name, age_days)
        tol = 1e-6 * max(
            abs(rng.lower) if np.isfinite(rng.lower) else 0.0,
            abs(rng.upper) if np.isfinite(rng.upper) else 0.0,
            1.0,
        )
        lo_hit = bool(np.isfinite(rng.lower) and float(iv[0]) <= rng.lower + tol)
        hi_hit = bool(np.isfinite(rng.upper) and float(iv[1]) >= rng.upper - tol)
        out[name] = lo_hit or hi_hit
    return out


def review_report(
    report: dict[str, Any],
    data: DiagnosisData,
    att: Attribution,
    *,
    chosen: Sequence[str] = (),
    rv: Review | None = None,
) -> dict[str, Any]:
    """Check the report's claims against the held-out data; returns the report with the
    ``gap``, ``separable`` and ``honesty`` sections added and any withdrawn claim marked.

    ``chosen`` are the options the diagnosis chose from the data
    (:func:`orbitcal.diagnose.span_options.choose_options`), stated in ``data.chosen_from_data``.
    """
    if "data" in report:
        report["data"]["chosen_from_data"] = list(chosen)
        share = float(np.count_nonzero(att.holdout)) / max(data.n, 1)
        report["data"]["holdout"] = (
            f"later time blocks (the last {share:.0%} of the samples) that no fit saw"
        )
    for e in report["effects"]:
        limited = _bound_limited(e, data.element_age_days)
        e["param_bound_limited"] = limited
        e["bound_limited"] = any(limited.values())
    rv = rv if rv is not None else review(data, att)
    inseparable = _inseparable(report, att, rv, data.element_age_days)
    _mark_withdrawn(report, att, rv, inseparable)
    changed = rv.keep != list(att.selected)
    if changed or rv.blockless:
        _final_section(report, data, att, rv)
    if changed and rv.verdict != report["verdict"] and report["verdict"] == "none":
        # named by its own test where the selection named nothing (its status is set below)
        report["verdict"] = rv.verdict
        report["verdict_confidence"] = None
    elif changed and rv.verdict != report["verdict"]:
        # the attribution's status spoke of the verdict withdrawn, not of this one
        report["verdict_status"] = (
            f"{rv.verdict} stands after the review withdrew {report['verdict']} (see each "
            "effect's status); no resampling confidence"
        )
        report["verdict"] = rv.verdict
        report["verdict_confidence"] = None
    report["gap"] = gap_section(
        report,
        data,
        rv.final.residual_nt,
        rv.final.rms_nt,
        att.holdout,
        inseparable,
        beside=(
            (list(rv.keep), att.beside_final)
            if att.beside_final and sorted(rv.keep) == sorted(att.beside_final_of)
            else None
        ),
    )
    absorbed = absorbed_candidates(att)
    report["gap"]["absorbed_by_calibration"] = absorbed
    verdict_status(report, absorbed, OWN_TEST)
    if rv.rotation is not None and rv.rotation.named and report["verdict"] == ATTITUDE:
        report["verdict_confidence"] = None
        report["verdict_status"] = (
            "tentative: attitude_error is "
            + rv.rotation.words()
            + "; what would decide: "
            + deciders([ATTITUDE])
        )
    extrapolation_words(report, data, att, own_test=OWN_TEST)
    confounding_words(
        report,
        data,
        att,
        _fit_names(att),
        verdict_stands=report["verdict"] in att.selected
        and bool(rv.keep)
        and rv.keep[0] == report["verdict"],
        own_test=OWN_TEST,
    )
    report["honesty"] = _honesty_section(rv)
    return report


#: The status of an attitude error named by :func:`orbitcal.diagnose.rotation.rotation_test`.
ROTATION_STATUS = "named by its rotation test"
#: The status of an effect the second selection left out as a withdrawn effect's twin.
SECOND_LOOK_TWIN = "twin of a withdrawn effect"


def _withdraw(
    by_name: dict[str, dict[str, Any]],
    names: Sequence[str],
    status: str,
    reason_key: str | None = None,
    reason: str = "",
) -> None:
    """Mark the effects ``names`` of the report not significant, with ``status`` and a reason."""
    for name in names:
        e = by_name[name]
        e["significant"] = False
        e["status"] = status
        if reason_key is not None:
            e[reason_key] = reason


def _inseparable(
    report: dict[str, Any], att: Attribution, rv: Review, age_days: float | None
) -> list[str]:
    """The candidates the span cannot tell from the calibration
    (:func:`~orbitcal.diagnose.honesty.inseparable_candidates`) but those that stand with a
    measured size (:func:`orbitcal.diagnose.claims.size_measured`): most of such an effect's
    field is a change of the 12 parameters, and the rest fixes its size, so the report says so
    (``absorbed_reason``) and not that it cannot be separated."""
    from orbitcal.diagnose.claims import size_measured

    by_name = {e["name"]: e for e in report["effects"]}
    out = []
    for name in inseparable_candidates(att):
        e = by_name[name]
        if name in rv.keep and size_measured(e, age_days=age_days):
            e["absorbed_reason"] = (
                f"{float(e.get('absorbed_by_calibration_fraction') or 0.0):.1%} of its fitted "
                "field looks like a change of the 12 calibration parameters; the rest, which no "
                "change of them produces, measures its size (its 90 % intervals) and shrinks "
                "the held-out residual"
            )
            continue
        out.append(name)
    return out


def _mark_withdrawn(
    report: dict[str, Any],
    att: Attribution,
    rv: Review,
    inseparable: Sequence[str] | None = None,
) -> None:
    """Each effect the review withdrew: not significant, its status and the reason
    (``inseparable``: the candidates the span cannot tell from the calibration, by default
    :func:`~orbitcal.diagnose.honesty.inseparable_candidates`)."""
    if inseparable is None:
        inseparable = inseparable_candidates(att)
    by_name = {e["name"]: e for e in report["effects"]}
    residues = [r for r in rv.residues if r["possible_residue"]]
    for r in residues:
        _withdraw(
            by_name,
            [r["effect"]],
            "possible residue",
            "residue_reason",
            "possible residue: beside the other selected effects with a free scale per "
            "axis, a drift of it and a shift in time (their imperfect models), its field "
            f"shrinks the held-out residual by {r['gain']:.1%} (p = {r['p_value']:.2g}): "
            "what it takes may be what the others' templates miss",
        )
    for name, partner in rv.second_look_twins.items():
        _withdraw(
            by_name,
            [name],
            SECOND_LOOK_TWIN,
            "second_look_reason",
            f"indistinguishable on these data from {partner}, which the review withdrew: it "
            "would take the same gain, so the second selection left it out too",
        )
    _withdraw(by_name, rv.inseparable, "inseparable")
    _withdraw(by_name, rv.unlit, "unlit", "unlit_reason", UNLIT_REASON)
    for name in rv.stood_in:
        e = by_name[name]
        e["significant"] = True
        e["status"] = "selected"
        e["stands_in_for"] = list(rv.unlit)
        e["stand_in_reason"] = (
            f"significant on its own and a field fixed in space, as {', '.join(rv.unlit)} drew "
            "without an eclipse: in its place it shrinks the held-out residual significantly"
        )
    for name in inseparable:
        e = by_name[name]
        e["inseparable"] = True
        e["inseparable_reason"] = (
            "cannot be separated from the calibration on this span: "
            f"{float(e.get('absorbed_by_calibration_fraction') or 1.0):.1%} of its fitted field "
            "is a change "
            "of the 12 parameters, so its held-out gain says how it moves the calibration's "
            "extrapolation, not that it is present"
        )
    _withdraw(
        by_name,
        rv.overshadowed,
        "overshadowed",
        "overshadowed_reason",
        "a candidate the span cannot tell from the calibration explains the held-out "
        f"residual more than {OVERSHADOW_RATIO:g} x better than the model with it: its gain "
        "may be a fragment of the same misfit",
    )
    _withdraw(
        by_name,
        rv.immaterial,
        "immaterial",
        "immaterial_reason",
        f"it removes less than {MATERIAL_GAIN:.0%} of a held-out residual more than "
        f"{LARGE_GAP_TIMES_NOISE:g} x the noise floor: on a span shorter than an orbit that "
        "residual is one smooth misfit whose chunks are not independent, and a gain this "
        "small is what bending the calibration's extrapolation does",
    )
    _withdraw(
        by_name,
        rv.correlated,
        "not significant on correlated chunks",
        "correlated_reason",
        "its held-out gain comes and goes with a slow wander of the residual: counted as "
        "the independent stretches it spans (the chunks' autocorrelation), it is not "
        f"significant at {CORRELATED_ALPHA:g}",
    )
    for name in rv.blockless:
        by_name[name]["model_left_out_reason"] = (
            _quiet_only_words(rv.quiet_rms_nt)
            if name in rv.quiet_only and rv.quiet_rms_nt is not None
            else (
                "named by the shape of the held-out residual (rotation_reason says why); its "
                "model does not forecast the held-out blocks: the final model leaves it out"
                if name == ATTITUDE and name not in rv.quiet_only
                else "named by its own regional test, but its fitted model predicted the "
                "held-out blocks worse than none: the final model leaves it out"
            )
        )
    for name, (variation, wander) in rv.wander.items():
        reason = wander_reason(variation, wander, along_b=name in ACROSS_B)
        _withdraw(by_name, [name], "wander", "wander_reason", reason)
    _withdraw(
        by_name,
        rv.weak,
        "weak",
        "weak_reason",
        "the calibration's residual at |magnetic latitude| > 55 deg exceeds the quiet "
        f"latitudes' by less than {WEAK_CURRENTS_NT:g} nT: quiet-time auroral currents of a few "
        "nT, present at high latitude in any orbit, detected but not what the calibration "
        "disagrees about",
    )
    _withdraw(
        by_name,
        rv.orphaned,
        "withdrawn",
        "withdrawn_reason",
        "significant only beside "
        + ", ".join(_withdrawn_before_orphans(rv))
        + ": without them it no longer shrinks the held-out residual significantly",
    )
    _withdraw(
        by_name,
        rv.withdrawn,
        "withdrawn",
        "withdrawn_reason",
        "the final model with it was worse on the held-out blocks than the calibration alone",
    )
    if rv.rotation is not None:
        # after the wander test's withdrawal, which the rotation test may refute
        e = by_name[ATTITUDE]
        e["rotation_test"] = rv.rotation.to_json()
        if rv.rotation.named:
            e["significant"] = True
            e["status"] = ROTATION_STATUS
            e["rotation_reason"] = rv.rotation.words()


def _final_section(
    report: dict[str, Any], data: DiagnosisData, att: Attribution, rv: Review
) -> None:
    """The report's ``final`` section and effect order for the effects that stand."""
    from orbitcal.diagnose.report import _clean
    from orbitcal.diagnose.where import where_analysis

    keep, final = rv.keep, rv.final
    by_name = {e["name"]: e for e in report["effects"]}
    report["final"]["effects"] = [n for n in keep if n not in rv.blockless]
    if rv.blockless:
        report["final"]["named_without_model"] = list(rv.blockless)
    report["final"]["holdout_rms_nt"] = round(final.rms_nt / np.sqrt(3.0), 4)
    report["final"]["norm_holdout_rms_nt"] = round(final.rms_nt, 4)
    report["final"]["shrink"] = round(att.baseline_rms_nt / max(final.rms_nt, 1e-12), 4)
    report["final"]["where"] = (
        _clean(where_analysis(data, final.residual_nt, holdout=att.holdout)) if keep else None
    )
    report["effects"] = [by_name[n] for n in keep] + [
        e for e in report["effects"] if e["name"] not in keep
    ]


def _withdrawn_before_orphans(rv: Review) -> list[str]:
    """The effects whose withdrawal can leave another significant only beside them: not
    separable, unlit, possible residues, then those of the correlated-chunk and wander tests
    (each once, in that order)."""
    names = [
        *rv.inseparable,
        *rv.unlit,
        *(r["effect"] for r in rv.residues if r["possible_residue"]),
        *rv.correlated,
        *rv.wander,
    ]
    return list(dict.fromkeys(names))


def _honesty_section(rv: Review) -> dict[str, Any]:
    return {
        "residue_tests": rv.residues,
        "possible_residue": [r["effect"] for r in rv.residues if r["possible_residue"]],
        "inseparable": list(rv.inseparable),
        "unlit": list(rv.unlit),
        "stood_in": list(rv.stood_in),
        "orphaned": list(rv.orphaned),
        "overshadowed": list(rv.overshadowed),
        "immaterial": list(rv.immaterial),
        "correlated": list(rv.correlated),
        "weak": list(rv.weak),
        "wander": list(rv.wander),
        "fell_back": rv.fell_back,
        "withdrawn": rv.withdrawn,
        "named_without_model": list(rv.blockless),
        "rotation_test": None if rv.rotation is None else rv.rotation.to_json(),
        "second_look": list(rv.second_look),
        "statement": _fall_back_words(rv),
        **({"second_look_statement": _second_look_words(rv)} if rv.second_look else {}),
    }


def _second_look_words(rv: Review) -> str:
    """What the second selection did (:func:`orbitcal.diagnose.honesty.second_look_exclusions`)."""
    withdrawn = [n for n in rv.second_look if n not in rv.second_look_twins]
    twins = list(rv.second_look_twins)
    without = ", ".join(withdrawn) + (f" (and its twin {', '.join(twins)})" if twins else "")
    return (
        f"the review withdrew {', '.join(withdrawn)} from the first selection and left a gap: the "
        f"selection ran again without {without}, and its result, reviewed in turn, stands: "
        f"{', '.join(rv.keep) or 'none'}"
    )


def _quiet_only_words(rms: tuple[float, float, float, float]) -> str:
    """Why an effect judged on quiet latitudes is named without a model in the final fit."""
    with_q, base_q, with_all, base_all = (rms_nt_from_norm(x) for x in rms)
    return (
        "named where it was judged, on quiet magnetic latitudes beside the auroral currents: "
        f"there the final model with it holds the held-out residual to {with_q:.4g} nT "
        f"against {base_q:.4g} nT for the calibration alone; on every held-out sample, where "
        "the currents' unmodelled field dominates, it was not better "
        f"({with_all:.6g} against {base_all:.6g} nT), so the final model leaves it out"
    )


def _fall_back_words(rv: Review) -> str:
    if not rv.fell_back:
        return "the final model is no worse than the calibration alone on the held-out blocks"
    out = "the selected model was worse on the held-out blocks than the calibration alone: "
    parts = []
    if rv.withdrawn:
        parts.append(f"{', '.join(rv.withdrawn)} withdrawn")
    own = [n for n in rv.blockless if n not in rv.quiet_only]
    if own:
        parts.append(
            f"{', '.join(own)} left out of the final model but still named by "
            "their own regional test (their fitted model did not predict the held-out "
            "crossings)"
        )
    if rv.quiet_only:
        one = len(rv.quiet_only) == 1
        whose = "its" if one else "each one's"
        parts.append(
            f"{', '.join(rv.quiet_only)} left out of the final model but still named on the "
            f"quiet latitudes where {'it was' if one else 'they were'} judged (see {whose} "
            "model_left_out_reason)"
        )
    return out + "; ".join(parts)
