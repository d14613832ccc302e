"""The words of a reviewed diagnosis (issue 25): the gap, why each close candidate was refused,
what would decide, and a verdict status built from the same numbers.

:mod:`orbitcal.diagnose.honesty` decides what the held-out data allow the report to claim; this
module says it: the white-noise floor of the final residual (:func:`noise_floor_nt`), the
``gap`` section (:func:`gap_section`) and the verdict's status (:func:`verdict_status`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.noise import (
    ISOLATED_SIGMAS,
    isolated_samples,
    noise_floor_nt,
    without_isolated,
)

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.effects import DiagnosisData

__all__ = [
    "FIRM_CONFIDENCE",
    "GAP_TIMES_NOISE",
    "GENERAL_DECIDERS",
    "INSEPARABLE_LIMIT",
    "deciders",
    "gap_section",
    "noise_floor_nt",
    "noise_ratio",
    "refusal",
    "verdict_status",
]

#: A held-out residual more than this many times the noise floor is an unexplained gap [-].
GAP_TIMES_NOISE = 1.5
#: Share of an effect's fitted field (training energy) that a change of the 12 calibration
#: parameters reproduces, at or above which the span cannot tell the effect from the calibration
#: at all (issue 25): what is left of its field is <= 10 % in amplitude, and its held-out gain then
#: measures how it changes the calibration's extrapolation, not its own shape. Under nadir
#: pointing on the real Swarm storm pass every candidate but the crust reaches 0.985-1.0 (a
#: uniform external field, a time shift, a drift and a stray field all look like a change of
#: scale and offset there), so none of them can be named.
INSEPARABLE_LIMIT = 0.99
#: A candidate the span cannot tell from the calibration that leaves less than 1 / this of the
#: selected model's held-out residual overshadows the selection
#: (:func:`orbitcal.diagnose.honesty._overshadowed`).
OVERSHADOW_RATIO = 2.0
#: As :data:`orbitcal.diagnose.report.FIRM_CONFIDENCE`: below it a verdict is not stable.
FIRM_CONFIDENCE = 0.8


#: What data would decide, beyond the closest candidates' own needs.
GENERAL_DECIDERS = (
    "a prior calibration (orbitcal diagnose --calibration CAL.json)",
    "a longer span (more orbits in the training and held-out blocks)",
    "other attitudes (body rates and orientations that move each axis through the field)",
)


def noise_ratio(
    residual_nt: FloatArray, norm_rms_nt: float, mask: BoolArray | None
) -> tuple[float, float, float]:
    """The white-noise floor of ``residual_nt`` on ``mask`` [nT], the held-out RMS per component
    [nT] (``norm_rms_nt`` / sqrt 3, as the floor) and their ratio [-] (nan without a floor)."""
    sigma = noise_floor_nt(residual_nt, mask)
    rms = norm_rms_nt / np.sqrt(3.0)
    times = float(rms / sigma) if np.isfinite(sigma) and sigma > 0 else float("nan")
    return sigma, float(rms), times


def refusal(e: dict[str, Any]) -> str:
    if e.get("inseparable"):
        return str(e.get("inseparable_reason"))
    if e.get("status") == "implausible":
        return f"implausible: {e.get('implausible_reason')}"
    if e.get("status") == "not significant on correlated chunks":
        return f"not significant on correlated chunks: {e.get('correlated_reason')}"
    if e.get("status") == "immaterial":
        return f"immaterial: {e.get('immaterial_reason')}"
    if e.get("status") == "weak":
        return f"weak: {e.get('weak_reason')}"
    if e.get("status") == "wander":
        return f"within the noise's wander: {e.get('wander_reason')}"
    if e.get("status") == "unlit":
        return f"not the Sun's on this span: {e.get('unlit_reason')}"
    if e.get("status") == "possible residue":
        return str(e.get("residue_reason"))
    if e.get("second_look_reason"):
        return str(e.get("second_look_reason"))
    absorbed = e.get("absorbed_by_calibration_fraction")
    if absorbed is not None and absorbed >= 0.9:
        return (
            f"absorbed by the calibration: {absorbed:.0%} of its fitted field is a change of the "
            "12 parameters on this span"
        )
    return (
        f"not significant: held-out shrink {e.get('shrink')} (p = {e.get('p_value')}), "
        "within what chance or the calibration's own error explain"
    )


#: A candidate whose field (fitted alone), beyond what the calibration takes of it, the final
#: model's effects could take up to this share is refused as contained in their model: the
#: held-out blocks cannot tell it from them. A time-tag error beside an along-track orbit error
#: under nadir pointing is one.
CONTAINED_LIMIT = 0.9

#: Statuses of a candidate's own entry that say more than its held-out test beside the final
#: model (the span cannot tell it, its gain came with a wander, there was no eclipse, ...).
_OWN_REFUSALS = (
    "not significant on correlated chunks",
    "immaterial",
    "weak",
    "wander",
    "unlit",
    "possible residue",
)


def _closest_beside(
    report: dict[str, Any],
    beside: tuple[Sequence[str], Mapping[str, Mapping[str, Any]]],
    final_rms_nt: float,
) -> list[dict[str, Any]]:
    """The :data:`~orbitcal.diagnose.attribution.engine.CLOSEST_CANDIDATES` of ``beside`` (not
    in the final model) that leave the least held-out residual beside it, with their numbers
    there and why each was refused."""
    from orbitcal.diagnose.attribution.engine import CLOSEST_CANDIDATES
    from orbitcal.metrics import rms_nt_from_norm

    kept, judged = beside
    by_name = {e["name"]: e for e in report["effects"]}
    words = ", ".join(kept)
    out = []
    # An effect named without a model in the final fit (by its own test) was not refused.
    ranked = sorted(
        ((n, v) for n, v in judged.items() if not by_name.get(n, {}).get("significant")),
        key=lambda kv: kv[1]["holdout_rms_nt"],
    )
    for name, v in ranked[:CLOSEST_CANDIDATES]:
        e = by_name.get(name, {})
        after = float(v["holdout_rms_nt"])
        shrink = final_rms_nt / max(after, 1e-12)
        contained = v.get("contained")
        if contained is not None and contained >= CONTAINED_LIMIT:
            why = (
                f"contained in the model of {words}: of its field (fitted alone), what the "
                f"calibration leaves is {contained:.0%} a change of their parameters on this "
                "span, so the data cannot tell whether it is present beside them"
            )
        elif v.get("implausible"):
            why = f"implausible beside {words}: {v['implausible']}"
        elif e.get("inseparable") or e.get("status") in _OWN_REFUSALS:
            why = refusal(e)
        elif float(v["p_value"]) < float(v["level"]):
            why = (
                f"too small beside {words}: held-out shrink {shrink:.4g} (p = "
                f"{float(v['p_value']):.3g}), below the least gain an effect must bring"
            )
        else:
            why = (
                f"not significant beside {words}: held-out shrink {shrink:.4g} (p = "
                f"{float(v['p_value']):.3g}, above the step's level {float(v['level']):.3g}, "
                "Bonferroni over its candidates)"
            )
        out.append(
            {
                "name": name,
                "holdout_rms_after_nt": round(float(rms_nt_from_norm(after)), 4),
                "shrink": round(shrink, 4),
                "refused_because": why,
            }
        )
    return out


def _closest_alone(report: dict[str, Any]) -> list[dict[str, Any]]:
    """The candidates not named that leave the least held-out residual fitted beside the
    calibration alone (their single fits), and why each was refused."""
    from orbitcal.diagnose.attribution.engine import CLOSEST_CANDIDATES

    ranked = sorted(
        (e for e in report["effects"] if not e["significant"]),
        key=lambda e: (e.get("holdout_rms_after_nt") is None, e.get("holdout_rms_after_nt") or 0.0),
    )
    return [
        {
            "name": e["name"],
            "holdout_rms_after_nt": e.get("holdout_rms_after_nt"),
            "shrink": e.get("shrink"),
            "refused_because": refusal(e),
        }
        for e in ranked[:CLOSEST_CANDIDATES]
    ]


def deciders(names: Sequence[str]) -> str:
    """What data would tell ``names`` from the calibration, each idea once."""
    from orbitcal.diagnose.report import SEPARATING_DATA

    ideas: dict[str, str] = {
        "a prior calibration": "a prior calibration (orbitcal diagnose --calibration CAL.json)"
    }
    for n in names:
        for part in SEPARATING_DATA.get(n, "").replace(" or ", ", ").split(", "):
            part = part.strip()
            # one entry per idea: "a longer span" and "a longer span (several orbits)" are one
            key = part.split(" (")[0]
            if part and key not in ideas:
                ideas[key] = part
    return "; ".join(ideas.values())


def gap_section(
    report: dict[str, Any],
    data: DiagnosisData,
    residual_nt: FloatArray,
    rms_nt: float,
    holdout: BoolArray,
    inseparable: Sequence[str] = (),
    beside: tuple[Sequence[str], Mapping[str, Mapping[str, Any]]] | None = None,
) -> dict[str, Any]:
    """The ``gap`` section: the final held-out residual against the noise floor, where it lies,
    the candidates that came closest to explaining it and why each was refused, and what data
    would decide.

    ``beside``: the effects of the final model and each other candidate fitted beside them
    (:attr:`orbitcal.diagnose.attribution.Attribution.beside_final`); the closest candidates are
    then judged on what the final model leaves, not against the calibration alone.
    """
    from orbitcal.diagnose.report import SEPARATING_DATA

    sigma, rms, times = noise_ratio(residual_nt, rms_nt, holdout)
    where = (report.get("final") or {}).get("where") or report.get("where") or {}
    isolated = isolated_samples(residual_nt, data.t_utc_s, sigma)
    held_isolated = isolated & holdout
    rms_all = rms
    if np.any(held_isolated):
        # The figures, and where the gap lies, without them (:mod:`orbitcal.diagnose.noise`).
        clean = holdout & ~isolated
        rms = float(np.sqrt(np.mean(np.asarray(residual_nt)[clean] ** 2)))
        times = rms / sigma
        where = _where_without(data, residual_nt, isolated, holdout)
    unexplained = bool(np.isfinite(times) and times > GAP_TIMES_NOISE)
    excess = float(np.sqrt(max(rms**2 - sigma**2, 0.0))) if np.isfinite(sigma) else float("nan")
    closest = (
        _closest_beside(report, beside, rms_nt) if beside is not None else _closest_alone(report)
    )
    decide = [
        *dict.fromkeys(SEPARATING_DATA[e["name"]] for e in closest if e["name"] in SEPARATING_DATA),
        *GENERAL_DECIDERS,
    ]
    gap: dict[str, Any] = {
        "unexplained": unexplained,
        "holdout_rms_nt": round(float(rms), 4),
        "noise_floor_nt": round(float(sigma), 4) if np.isfinite(sigma) else None,
        "times_noise": round(times, 2) if np.isfinite(times) else None,
        "excess_rms_nt": round(excess, 4) if np.isfinite(excess) else None,
        "noise_floor_from": "second differences of the final residual on the held-out samples "
        "(median absolute value): the white part of the noise",
        "where": {
            "concentration": where.get("concentration"),
            "axis_rms_nt": where.get("axis_rms_nt"),
        },
        "closest_candidates": closest,
        "closest_judged_beside": [] if beside is None else list(beside[0]),
        "would_decide": decide,
        "inseparable": list(inseparable),
        "isolated_samples": _isolated_entry(residual_nt, held_isolated, rms_all),
    }
    if inseparable:
        overshadowed = [e["name"] for e in report["effects"] if e.get("status") == "overshadowed"]
        one = len(inseparable) == 1
        gap["inseparable_statement"] = (
            f"the held-out residual ({rms:.3g} nT per component, {times:.1f} x the noise floor) "
            "cannot be separated from the calibration on this span: "
            + ", ".join(inseparable)
            + (" would shrink it" if one else " would each shrink it")
            + f", but >= {INSEPARABLE_LIMIT:.0%} of "
            + ("its" if one else "each one's")
            + " fitted field is a change of the 12 calibration parameters, so the held-out blocks "
            + (
                "cannot tell whether it is present"
                if one
                else "cannot tell which (if any) is present"
            )
            + _overshadowed_too(overshadowed)
            + "; what would decide: "
            + deciders([*inseparable, *overshadowed])
        )
    if unexplained:
        gap["statement"] = (
            f"an unexplained gap: the held-out residual is {rms:.3g} nT per component, "
            f"{times:.1f} x the noise floor ({sigma:.3g} nT); "
            + _unmodelled((report.get("final") or {}).get("named_without_model") or [])
            + _lies(where.get("concentration"))
            + _wandering(
                [e["name"] for e in report["effects"] if e.get("status") == "wander"],
                rotation=any(
                    (e.get("rotation_test") or {}).get("named") for e in report["effects"]
                ),
            )
            + _fixed_in_space(
                [e for e in report["effects"] if e.get("status") == "unlit"],
                stood_in=any(e.get("stands_in_for") for e in report["effects"]),
            )
            + _isolated_clause(gap["isolated_samples"])
        )
    else:
        gap["statement"] = (
            f"the held-out residual is at the noise floor ({times:.2f} x {sigma:.3g} nT)"
            + _isolated_clause(gap["isolated_samples"])
        )
    return gap


def _where_without(
    data: DiagnosisData, residual_nt: FloatArray, isolated: BoolArray, holdout: BoolArray
) -> dict[str, Any]:
    """Where the residual lies once its isolated samples are replaced by the running median
    around them."""
    from orbitcal.diagnose.where import where_analysis

    r = without_isolated(residual_nt, data.t_utc_s, isolated)
    return where_analysis(data, r, holdout=holdout)


def _isolated_entry(
    residual_nt: FloatArray, held_isolated: BoolArray, rms_all_nt: float
) -> dict[str, Any] | None:
    """The held-out isolated samples: how many, the largest component among them and the
    held-out RMS per component with them [nT] (None when there are none)."""
    k = int(np.count_nonzero(held_isolated))
    if k == 0:
        return None
    largest = float(np.max(np.abs(np.asarray(residual_nt)[held_isolated])))
    return {
        "count": k,
        "largest_component_nt": round(largest, 1),
        "holdout_rms_with_them_nt": round(float(rms_all_nt), 4),
        "left_out_because": "each differs from the median of the samples around it by more than "
        f"{ISOLATED_SIGMAS:g} x the noise floor while its neighbours do not (a spike, a wrong "
        "time tag, or a structure narrower than one sample step)",
    }


def _isolated_clause(entry: Mapping[str, Any] | None) -> str:
    """The clause of a gap statement for the isolated samples left out of its figures."""
    if not entry:
        return ""
    k = entry["count"]
    return (
        f"; {k} isolated held-out sample{'s' if k > 1 else ''} "
        f"({'spikes: up to' if k > 1 else 'a spike:'} "
        f"{entry['largest_component_nt']:.3g} nT in a component, far from both "
        f"neighbours) {'are' if k > 1 else 'is'} left out of these figures: with "
        f"{'them' if k > 1 else 'it'}, the held-out residual is "
        f"{entry['holdout_rms_with_them_nt']:.3g} nT per component"
    )


def verdict_status(
    report: dict[str, Any], absorbed: Sequence[str], own_test: frozenset[str]
) -> None:
    """``separable``, ``verdict_status`` (and, beside a gap, no ``verdict_confidence``) of a
    reviewed report, from the same numbers as its ``gap`` and ``separation`` sections.

    ``absorbed``: every candidate the calibration takes up whole on this span
    (:func:`orbitcal.diagnose.honesty.absorbed_candidates`); ``own_test``: the effects judged on
    their own latitudes (auroral currents)."""
    from orbitcal.diagnose.claims import resample_words

    gap = report["gap"]
    unseen = (
        _taken_whole(absorbed) + "; what would decide: " + deciders(absorbed)
        if absorbed and not gap["inseparable"]
        else ""
    )
    # Beside the candidates that would shrink the held-out residual, those the calibration takes
    # up so whole that they shrink nothing (a uniform external field under nadir pointing is a
    # change of scale): unseen as well, and said so.
    rest = [n for n in absorbed if n not in gap["inseparable"]]
    also = _taken_whole(rest, also=True) if rest and gap["inseparable"] else ""
    separation = {s["effect"]: s for s in report.get("separation") or []}
    verdict = report["verdict"]
    report["separable"] = None if verdict == "none" else verdict not in separation
    conf = report.get("verdict_confidence")
    if verdict == "none":
        if gap["unexplained"] and gap["inseparable"]:
            report["verdict_confidence"] = None
            report["verdict_status"] = "none: " + gap["inseparable_statement"] + also
        elif gap["unexplained"]:
            report["verdict_confidence"] = None
            report["verdict_status"] = "none: " + gap["statement"] + unseen
        else:
            report["verdict_status"] = "none: at the noise floor" + unseen
    elif verdict in own_test and gap["unexplained"] and gap["inseparable"]:
        report["verdict_status"] = (
            f"{verdict} on their own latitudes; beside them, " + gap["inseparable_statement"] + also
        )
    elif verdict in own_test and unseen:
        report["verdict_status"] = (
            f"{report.get('verdict_status') or 'firm'}: {verdict} on their own latitudes" + unseen
        )
    elif not report["separable"]:
        report["verdict_status"] = (
            (
                f"tentative: {verdict} is present"
                + (
                    f" (it wins in {resample_words(conf)} of the held-out blocks)"
                    if conf is not None
                    else ""
                )
                if conf is None or conf >= FIRM_CONFIDENCE
                else f"tentative: {verdict} is named by the held-out test but wins only in "
                f"{resample_words(conf)} of the held-out blocks"
            )
            + ", but its size cannot be separated from the calibration on this span "
            f"({separation[verdict]['absorbed_fraction']:.0%} of its field is a change of the 12 "
            f"parameters); what would separate it: {separation[verdict]['would_separate']}"
        )
        report["verdict_confidence_of"] = "presence"


def _overshadowed_too(over: Sequence[str]) -> str:
    """The clause naming the candidates withdrawn as overshadowed by one the calibration cannot
    be told from: they shrink the held-out residual too, but their gain cannot be separated from
    the calibration's misfit on this span either (the storm pass through a slow tumble: the
    external field took it from 316 to 38 nT per component, a drift of the 12 parameters to 22
    nT, and the report named neither the storm nor why)."""
    if not over:
        return ""
    one = len(over) == 1
    return (
        f"; {', '.join(over)} would shrink it too, but a change of the "
        f"calibration explains it more than {OVERSHADOW_RATIO:g} x better than the model with "
        f"{'it' if one else 'them'}: "
        f"{'its' if one else 'their'} gain cannot be separated from the calibration on this "
        "span either"
    )


def _taken_whole(names: Sequence[str], *, also: bool = False) -> str:
    """The clause saying that the calibration takes up ``names`` whole on this span."""
    one = len(names) == 1
    whose, who = ("its", "it") if one else ("each one's", "they")
    return (
        f"; the calibration {'also ' if also else ''}takes up {', '.join(names)} whole on this "
        f"span (>= {INSEPARABLE_LIMIT:.0%} of {whose} fitted field is a change of the 12 "
        f"parameters): if present, {who} cannot be separated from the calibration on this span"
        + (" either" if also else "")
    )


def _unmodelled(named: Sequence[str]) -> str:
    """What explains the gap: nothing, or named effects whose fitted model the final fit left
    out (auroral currents whose model predicted the held-out crossings worse than none, or
    effects named on the quiet latitudes beside them)."""
    if not named:
        return "no candidate explains it"
    one = len(named) == 1
    return (
        f"{', '.join(named)} {'is' if one else 'are'} named but {'has' if one else 'have'} no "
        "model in the final fit (each one's model_left_out_reason says why), so "
        f"{'its' if one else 'their'} field stays in this residual; no other candidate "
        "explains it"
    )


def _lies(concentration: object) -> str:
    """Where the gap lies, as a clause of the statement ("" when not known)."""
    if not concentration:
        return ""
    if concentration == "everywhere":
        return "; it is spread over all latitudes, in sunlight and in eclipse"
    if concentration == "sunlit":
        return "; it lies mostly in sunlight"
    if concentration == "eclipse":
        return "; it lies mostly in eclipse"
    return f"; it lies mostly at {concentration}"


def _fixed_in_space(unlit: Sequence[dict[str, Any]], *, stood_in: bool = False) -> str:
    """The clause of a gap statement for a Sun-driven field withdrawn for want of an eclipse
    (none when the external field stands in for it: the model holds that field then)."""
    if not unlit or stood_in:
        return ""
    e = unlit[0]
    before, after = e.get("holdout_rms_before_nt"), e.get("holdout_rms_after_nt")
    took = (
        f" (with {e['name']}'s template at its selection step the held-out residual went from "
        f"{before:.3g} to {after:.3g} nT per component)"
        if isinstance(before, float) and isinstance(after, float)
        else ""
    )
    return (
        f"; a field fixed in space may take up part of it{took}, as {e['name']}'s template "
        "draws it, but without an eclipse on a span shorter than an orbit nothing says it comes "
        "from the Sun: the ring current's field (external_field) is one such field; a "
        "sunlit/eclipse cycle would decide"
    )


def _wandering(names: Sequence[str], *, rotation: bool = False) -> str:
    """The clause of a gap statement for candidates withdrawn as within the noise's wander
    (``rotation``: the attitude error was named by the residual's shape, across B: the wander is
    the attitude's, not an offset's, which would lie along B as much)."""
    if not names:
        return ""
    like = (
        "a random walk of the attitude would (across the main field, see the attitude error's "
        "rotation_test)"
        if rotation
        else "a random-walk or 1/f offset of the sensor would (or a field no template draws)"
    )
    return (
        f"; it wanders slowly, as {like}, and {', '.join(names)} "
        f"{'is' if len(names) == 1 else 'are'} no "
        "larger than that wander (the floor above is the white part of the noise only)"
    )
