"""The model core's numbers in the section-5 report.

Under either engine every listed effect gets ``probability`` (its posterior inclusion
probability), the report ``verdict_probability`` (the verdict's; for ``"none"`` the probability
that no effect is present) and ``confirmation`` (the chosen model against the calibration alone
on the final block), plus a ``model`` section with the rest of the posterior. Under the
``"model"`` engine the verdict, the effects' ``significant`` flags and order, and ``final``'s
effects are the model core's too.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

from orbitcal.diagnose.model.core import ModelDiagnosis
from orbitcal.diagnose.options import ModelOptions

__all__ = [
    "event_named",
    "model_named",
    "model_section",
    "model_status",
    "splits",
    "unconfirmed",
    "with_model_keys",
]


def _p(x: float) -> float:
    return round(min(max(float(x), 0.0), 1.0), 4)


def model_named(md: ModelDiagnosis, options: ModelOptions) -> tuple[str, ...]:
    """The effects the model core names: those of its chosen model that the final block
    confirms. The chosen model must forecast the block better than the calibration alone
    (:meth:`Confirmation.passes` at the options' level); with several chosen effects, each must
    also forecast it better beside the others (its own test, Holm's step-down over the chosen
    effects at the same level). Beside them, an effect confirmed within the final block's events
    (:func:`event_named`). The first is the verdict (:func:`_verdict_key`)."""
    named = [*_forecast_named(md, options.confirmation_level), *event_named(md, options)]
    inc = md.inclusion()
    return tuple(sorted(named, key=lambda e: _verdict_key(md, inc.get(e, 0.0), e)))


def event_named(md: ModelDiagnosis, options: ModelOptions) -> tuple[str, ...]:
    """The effects whose within-event confirmation on the final block passes at the
    confirmation level over the number of such tests made (Bonferroni;
    :mod:`orbitcal.diagnose.model.within_event`)."""
    tests = md.event_confirmations
    level = options.confirmation_level / max(len(tests), 1)
    return tuple(e for e, c in tests.items() if c.passes(level))


def _forecast_named(md: ModelDiagnosis, level: float) -> tuple[str, ...]:
    """The chosen effects the forecast confirmation names (:func:`model_named`)."""
    if not md.chosen or not md.confirmation.passes(level):
        return ()
    if not md.effect_confirmations:
        return md.chosen
    rejected: set[str] = set()
    tests = sorted(md.effect_confirmations.items(), key=lambda kv: kv[1].p_value)
    for k, (name, conf) in enumerate(tests):
        if not conf.rejects(level / (len(tests) - k)):
            break  # Holm: the first p-value above its level stops the step-down
        rejected.add(name)
    # an effect whose test rejects but whose forecast is not closer is not named, and does not
    # stop the others' step-down (the order is the p-values')
    return tuple(e for e in md.chosen if e in rejected and md.effect_confirmations[e].closer())


def _verdict_key(md: ModelDiagnosis, probability: float, effect: str) -> tuple[float, float]:
    """Named effects in order, the verdict first: the contract's "the effect that explains most
    of the gap", the one whose removal from the chosen model (both fitted on the training span)
    costs the final block most RMS; the surer first among equal ones. Until 2026-11-29 the order
    was the probability's (to two decimals), the final block's RMS only breaking ties. An
    effect named by its events counts what its within-event prediction takes; the one effect of
    a chosen model, what the model's forecast takes."""
    conf = md.effect_confirmations.get(effect) or md.event_confirmations.get(effect)
    if conf is None and md.chosen == (effect,):
        conf = md.confirmation
    shrink = conf.holdout_rms_before_nt - conf.holdout_rms_after_nt if conf else 0.0
    return (-shrink, -probability)


def unconfirmed(md: ModelDiagnosis, options: ModelOptions) -> tuple[str, ...]:
    """The chosen effects that the final block did not confirm (:func:`model_named`)."""
    named = model_named(md, options)
    return tuple(e for e in md.chosen if e not in named)


def _percent(x: float) -> str:
    return f"{100.0 * x:.0f} %"


def model_status(md: ModelDiagnosis, options: ModelOptions) -> str:
    """The verdict's status in words, from the model core's own numbers: what it names and
    with what probability; what it chose on the training span but the final block did not
    confirm; which pairs the posterior cannot tell apart; and which candidates the calibration
    mostly reproduces on this span (more than half of their prior field is a change of the 12
    parameters), so that the data cannot separate them from it."""
    named = _forecast_named(md, options.confirmation_level)
    by_events = event_named(md, options)
    inc = md.inclusion()
    conf = md.confirmation
    before, after = conf.holdout_rms_before_nt, conf.holdout_rms_after_nt
    block = f"{before:.1f} -> {after:.1f} nT, p {conf.p_value:.2g}"

    def listed(names: Sequence[str]) -> str:
        return ", ".join(f"{e} (probability {inc[e]:.2f})" for e in names)

    left = unconfirmed(md, options)
    parts = []
    if named:
        parts.append(
            f"named by the model core: {listed(named)}; confirmed on the final block ({block})"
        )
        if left:
            parts.append(
                f"beside them, not confirmed on its own on the final block: {listed(left)}"
            )
    elif md.chosen and conf.passes(options.confirmation_level):
        parts.append(
            f"none named alone: the chosen model, {listed(md.chosen)}, forecasts the final block "
            f"better together ({block}), but none of them does beside the others, so the final "
            f"block cannot tell which of {', '.join(md.chosen)} carries the gain"
        )
    elif md.chosen:
        parts.append(
            f"{'' if by_events else 'none: '}the model chosen on the training span, "
            f"{listed(md.chosen)}, does not forecast the final block better than the "
            f"calibration alone ({block})"
        )
    elif not by_events:
        parts.append("none")
    for e in by_events:
        ev = md.event_confirmations[e]
        parts.append(
            f"named by its events: {e}, whose amplitudes change from event to event (no fit on "
            "the training span forecasts them): each event of the final block fitted on part "
            f"of it predicts the rest ({ev.holdout_rms_before_nt:.1f} -> "
            f"{ev.holdout_rms_after_nt:.1f} nT, p {ev.p_value:.2g}); probability "
            f"{inc.get(e, 0.0):.2f} from the training span's events"
        )
    cutoff = options.selection_probability
    for e, p in md.event_probability.items():
        if p >= cutoff and e not in by_events:
            parts.append(
                f"{e} (probability {p:.2f} from the training span's events) not confirmed "
                "within the final block's events"
                + ("" if e in md.event_confirmations else " (the block holds none)")
            )
    parts.extend(s["statement"] for s in splits(md, options.selection_probability))
    mostly = sorted(
        ((e, a) for e, a in md.absorbed.items() if a > 0.5 and e not in (*named, *by_events)),
        key=lambda kv: -kv[1],
    )
    if mostly:
        parts.append(
            "on this span most of the field of "
            + ", ".join(f"{e} ({_percent(a)})" for e, a in mostly)
            + " is a change of the 12 calibration parameters: if present, they cannot be "
            "separated from the calibration; what would decide: a prior calibration (orbitcal "
            "diagnose --calibration CAL.json), a longer span, attitude diversity"
        )
    return "; ".join(parts)


def splits(md: ModelDiagnosis, cutoff: float) -> list[dict[str, Any]]:
    """Pairs the posterior cannot tell apart: together probably one is present (``P(A or B)``
    at least ``cutoff``) while neither alone reaches it."""
    inc = md.inclusion()
    out = []
    # effects judged by their events have no joint posterior with the others
    joint = [e for e in md.posterior.effects if e not in md.event_probability]
    for a, b in itertools.combinations(joint, 2):
        both = md.posterior.pair(a, b)
        either = inc[a] + inc[b] - both
        if either >= cutoff and max(inc[a], inc[b]) < cutoff:
            out.append(
                {
                    "effects": [a, b],
                    "probability_either": _p(either),
                    "probability_both": _p(both),
                    "statement": f"cannot tell {a} from {b}: one of them is present with "
                    f"probability {either:.2f}, {a} {inc[a]:.2f}, {b} {inc[b]:.2f}",
                }
            )
    return sorted(out, key=lambda s: -s["probability_either"])


def model_section(md: ModelDiagnosis, options: ModelOptions) -> dict[str, Any]:
    """The report's ``model``: the posterior, the noise model, what the calibration absorbs."""
    inc = md.inclusion()
    named = model_named(md, options)
    return {
        "engine": options.engine,
        "inclusion_probability": {e: _p(p) for e, p in sorted(inc.items(), key=lambda kv: -kv[1])},
        "probability_none": _p(md.posterior.none()),
        "chosen": list(md.chosen),
        "cross_validation": md.crossval.to_json(),
        "confirmed": bool(named),
        "named": list(named),
        "not_confirmed": list(unconfirmed(md, options)),
        "effect_confirmations": {e: c.to_json() for e, c in md.effect_confirmations.items()},
        "fitted_beside": list(md.beside),
        "event_probability": {e: _p(p) for e, p in md.event_probability.items()},
        "event_confirmations": {e: c.to_json() for e, c in md.event_confirmations.items()},
        "splits": splits(md, options.selection_probability),
        "absorbed_by_calibration_fraction": {e: _p(a) for e, a in md.absorbed.items()},
        "forms": dict(md.forms),
        "params": {e: {k: float(f"{v:.6g}") for k, v in p.items()} for e, p in md.params.items()},
        "noise": [n.describe() for n in md.noise],
        "models_evaluated": len(md.posterior.models),
        "settings": {
            "expected_effects": options.expected_effects,
            "max_effects": options.max_effects,
            "noise_max_order": options.noise_max_order,
            "prior_sd_fraction": round(options.prior_sd_fraction, 6),
            "selection_probability": options.selection_probability,
            "confirmation_level": options.confirmation_level,
        },
    }


def with_model_keys(
    document: dict[str, Any], md: ModelDiagnosis, options: ModelOptions
) -> dict[str, Any]:
    """``document`` (a section-5 report) with the model core's keys; under the ``"model"``
    engine, its verdict too."""
    for entry in document["effects"]:
        entry["probability"] = _p(md.probability(entry["name"]))
    if options.engine == "model":
        named = model_named(md, options)
        document["verdict"] = named[0] if named else "none"
        for entry in document["effects"]:
            entry["significant"] = entry["name"] in named
            if entry.get("status") != "implausible":
                entry["status"] = "selected" if entry["significant"] else "not significant"
        # ranked, most explanatory first (CONTRACT section 5): the named effects in the
        # verdict's order, then the rest by probability
        rank = {e: k for k, e in enumerate(named)}
        document["effects"].sort(key=lambda e: (rank.get(e["name"], len(rank)), -e["probability"]))
        document.setdefault("final", {})["effects"] = list(named)
        document["verdict_status"] = model_status(md, options)
    document["verdict_probability"] = _p(md.probability(document["verdict"]))
    document["confirmation"] = md.confirmation.to_json()
    document["model"] = model_section(md, options)
    return document
