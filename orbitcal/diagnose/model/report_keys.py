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
from typing import Any

from orbitcal.diagnose.model.core import ModelDiagnosis
from orbitcal.diagnose.options import ModelOptions

__all__ = ["model_named", "model_section", "splits", "with_model_keys"]


def _p(x: float) -> float:
    return round(min(max(float(x), 0.0), 1.0), 4)


def model_named(md: ModelDiagnosis, options: ModelOptions) -> tuple[str, ...]:
    """The effects the model core names: its chosen model when the confirmation passes at the
    options' level, else none."""
    if md.chosen and md.confirmation.p_value <= options.confirmation_level:
        return md.chosen
    return ()


def splits(md: ModelDiagnosis, cutoff: float) -> list[dict[str, Any]]:
    """Pairs the posterior cannot tell apart: together probably one is present (``P(A or B)``
    at least ``cutoff``) while neither alone reaches it."""
    inc = md.inclusion()
    out = []
    for a, b in itertools.combinations(md.posterior.effects, 2):
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
        document["effects"].sort(key=lambda e: -e["probability"])
        document.setdefault("final", {})["effects"] = list(named)
        document["verdict_status"] = (
            "none"
            if not named
            else f"named by the model core, probability {md.probability(named[0]):.2f}"
        )
    document["verdict_probability"] = _p(md.probability(document["verdict"]))
    document["confirmation"] = md.confirmation.to_json()
    document["model"] = model_section(md, options)
    return document
