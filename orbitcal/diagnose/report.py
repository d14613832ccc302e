"""The diagnosis report: CONTRACT section-5 JSON and a self-contained HTML page.

JSON keys of section 5 are written exactly: ``baseline {method, holdout_rms_nt}``, ``verdict``,
``effects [{name, significant, holdout_rms_before_nt, holdout_rms_after_nt, shrink, params}]``
(ranked, most explanatory first) and ``where {axis_rms_nt, ...}``. Supporting sections are added
around them (``final``, ``split_fits``, ``learned``, ``data``).

The HTML page is drawn from this JSON alone by :mod:`orbitcal.diagnose.html_report`
(``report_html``), so the command line and the service render the same page.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from orbitcal.diagnose.attribution import Attribution, EffectScore, SplitFit
from orbitcal.diagnose.effects import EFFECT_NAMES, DiagnosisData, get_effect

__all__ = ["BASELINE_METHOD", "build_report"]


#: Name of the baseline calibration in the report.
BASELINE_METHOD = "linear-12"


def _num(x: float) -> float | None:
    """JSON-safe float (NaN/inf -> None), rounded to 1e-4."""
    return None if not math.isfinite(x) else round(float(x), 4)


def _outward(interval: Sequence[float]) -> list[float | None]:
    """An interval on the report's 1e-4 grid, rounded outward: rounded to nearest, a bound
    moved inward by up to 5e-5 (a sixtieth of a time offset's 90 % interval of 3 ms), and an
    interval stated narrower than measured."""
    lo, hi = float(interval[0]), float(interval[1])
    return [
        None if not math.isfinite(lo) else math.floor(round(lo * 1e4, 6)) / 1e4,
        None if not math.isfinite(hi) else math.ceil(round(hi * 1e4, 6)) / 1e4,
    ]


def _rms(norm_rms: float) -> float | None:
    """The attribution's ``sqrt(mean |r|²)`` as the contract's ``*_rms_nt`` (per component,
    :mod:`orbitcal.metrics`): the same number as ``orbitcal calibrate`` and the service."""
    from orbitcal.metrics import rms_nt_from_norm

    return _num(rms_nt_from_norm(norm_rms))


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return _num(obj)
    return obj


#: What data would separate each effect from the calibration when the span cannot.
SEPARATING_DATA: dict[str, str] = {
    "temperature": "a sunlit/eclipse cycle (a temperature swing) or a prior calibration",
    "magnetorquer": "magnetorquer commands switching on and off",
    "time_offset": "attitude diversity (changing body rates) or a prior calibration",
    "external_field": "a prior calibration (--calibration), a longer span (several orbits) "
    "or attitude diversity",
    "crustal_field": "a longer span with repeated ground tracks",
    "sun_driven": "a sunlit/eclipse cycle or a prior calibration",
    "nonlinearity": "attitude diversity (each axis through the whole field range)",
    "orbit_error": "a longer span or measured (GNSS) positions",
    "parameter_drift": "a longer span or a prior calibration",
    "field_aligned_currents": "more auroral crossings",
    "attitude_error": "attitude diversity or a longer span",
}

#: Share of an effect's fitted field a change of the 12 parameters reproduces, above which the
#: span cannot separate the two without a prior calibration.
ABSORBED_LIMIT = 0.9
#: Verdict confidence below which the verdict is reported as tentative.
FIRM_CONFIDENCE = 0.8


def _separation(att: Attribution, age_days: float | None = None) -> list[dict[str, Any]]:
    """Selected effects the span cannot separate from the calibration, and what data would.

    An effect most of whose field the 12 parameters absorb is still separated when the rest of
    its field measures its size (:func:`orbitcal.diagnose.claims.measured_parameters`: a tight
    90 % interval of the joint fit), as a time-tag error's dt = −0.498 s (90 %: −0.499 …
    −0.496 s) at 99.6 % absorbed: the report then says what is absorbed, not that its size is
    unknown."""
    from orbitcal.diagnose.claims import measured_parameters

    if att.has_prior:
        return []
    out = []
    for e in att.effects:
        if not e.significant or e.absorbed_fraction is None:
            continue
        measured = e.holdout_rms_after_nt < e.holdout_rms_before_nt and measured_parameters(
            e.name, e.params, e.intervals, age_days=age_days
        )
        if e.absorbed_fraction >= ABSORBED_LIMIT and not measured:
            out.append(
                {
                    "effect": e.name,
                    "absorbed_fraction": e.absorbed_fraction,
                    "statement": (
                        f"{e.absorbed_fraction:.0%} of the fitted {e.name} field is what a change "
                        "of the 12 calibration parameters also produces on this span "
                        f"({att.span_s / 3600.0:.1f} h): its size is not separable from the "
                        "calibration, only its presence"
                    ),
                    "would_separate": SEPARATING_DATA.get(e.name, "a prior calibration"),
                }
            )
    return out


def _verdict_status(att: Attribution, separation: list[dict[str, Any]]) -> str:
    if att.verdict == "none":
        return "none"
    if any(s["effect"] == att.verdict for s in separation):
        return "tentative: not separable from the calibration on this span"
    if att.verdict_confidence is not None and att.verdict_confidence < FIRM_CONFIDENCE:
        return "tentative: another candidate wins in some resamples of the held-out blocks"
    return "firm"


def build_report(
    data: DiagnosisData,
    att: Attribution,
    where: dict[str, Any],
    *,
    learned: dict[str, Any] | None = None,
    where_final: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Assemble the section-5 report from the attribution and where-analysis.

    ``where`` locates the calibration-only residual; ``where_final`` (optional) locates what the
    selected effects leave, e.g. the auroral part of a storm once the ring current is modelled.
    """
    separation = _separation(att, data.element_age_days)
    report: dict[str, Any] = {
        "baseline": _baseline_section(data, att),
        "verdict": att.verdict,
        "verdict_confidence": _num(att.verdict_confidence)
        if att.verdict_confidence is not None
        else None,
        "verdict_status": _verdict_status(att, separation),
        "separation": _clean(separation),
        "effects": [_effect_entry(e, data.element_age_days) for e in att.effects],
        "where": _clean(where),
        "final": _final_section(att, where_final),
        "split_fits": [_split_fit_entry(s) for s in att.split_fits],
        "data": _data_section(data, att),
    }
    if learned is not None:
        report["learned"] = _clean(learned)
    report["provenance"] = _provenance(data, att)
    return report


def _effect_entry(e: EffectScore, age_days: float | None = None) -> dict[str, Any]:
    """One effect's entry of the report's ``effects`` (``remark``: what its values say beyond
    the verdict, :func:`_remark`)."""
    entry = {
        "name": e.name,
        "significant": bool(e.significant),
        "holdout_rms_before_nt": _rms(e.holdout_rms_before_nt),
        "holdout_rms_after_nt": _rms(e.holdout_rms_after_nt),
        "shrink": _num(e.shrink),
        "params": _clean(e.params),
        "p_value": float(f"{e.p_value:.3g}"),
        "unique_rms_increase_nt": _rms(e.unique_rms_increase_nt),
        "selection_step": e.step,
        "witness": get_effect(e.name).witness,
        "status": (
            "implausible" if e.implausible else ("selected" if e.significant else "not significant")
        ),
        "implausible_reason": e.implausible,
        "param_intervals_90": {k: _outward(v) for k, v in e.intervals.items()},
        "shrink_interval_90": _clean(list(e.shrink_interval))
        if e.shrink_interval is not None
        else None,
        "absorbed_by_calibration_fraction": _num(e.absorbed_fraction)
        if e.absorbed_fraction is not None
        else None,
    }
    remark = _remark(e, age_days)
    if remark:
        entry["remark"] = remark
    return entry


def _remark(e: EffectScore, age_days: float | None) -> str | None:
    """An orbit error drifting faster than drag makes an element set drift: the words that it
    points to a manoeuvre after the element set's epoch (the range allows one,
    ``docs/diagnosis_priors.md``)."""
    from orbitcal.diagnose.bounds import DRAG_RATE_KM_PER_DAY

    rate = e.params.get("along_track_rate_km_per_day") if e.name == "orbit_error" else None
    if not isinstance(rate, int | float) or abs(float(rate)) <= DRAG_RATE_KM_PER_DAY:
        return None
    old = f" {abs(age_days):.1f} days old" if age_days is not None else ""
    return (
        f"the element set drifts from the spacecraft at {float(rate):.0f} km/day, more than drag "
        f"makes an element set{old} drift (<= {DRAG_RATE_KM_PER_DAY:g} km/day): a manoeuvre "
        "after its epoch? An element set from after it, or measured (GNSS) positions, would tell"
    )


def _baseline_section(data: DiagnosisData, att: Attribution) -> dict[str, Any]:
    """The report's ``baseline``: the calibration alone."""
    return {
        "method": BASELINE_METHOD,
        "holdout_rms_nt": _rms(att.baseline_rms_nt),
        "norm_holdout_rms_nt": _num(att.baseline_rms_nt),
        "train_rms_nt": _rms(att.baseline_train_rms_nt),
        "n_holdout": int(np.count_nonzero(att.holdout)),
        "reference_field": data.reference_field,
        "calibration_prior": (
            data.calibration_prior.summary() if data.calibration_prior is not None else None
        ),
    }


def _final_section(att: Attribution, where_final: dict[str, Any] | None) -> dict[str, Any]:
    """The report's ``final``: the selected effects' model."""
    return {
        "effects": list(att.selected),
        # selected by a forward step, removed again when re-tested beside the others
        "dropped": list(att.dropped),
        "holdout_rms_nt": _rms(att.final_rms_nt),
        "norm_holdout_rms_nt": _num(att.final_rms_nt),
        "shrink": _num(att.baseline_rms_nt / max(att.final_rms_nt, 1e-12)),
        "where": _clean(where_final) if where_final is not None else None,
    }


def _split_fit_entry(s: SplitFit) -> Any:
    """One entry of the report's ``split_fits``."""
    return _clean(
        {
            "name": s.name,
            "labels": s.labels,
            "offsets_nt": s.offsets_nt,
            "scales": s.scales,
            "max_offset_difference_nt": s.max_offset_difference_nt,
            "z": s.z,
            "flagged": s.flagged,
        }
    )


def _data_section(data: DiagnosisData, att: Attribution) -> dict[str, Any]:
    """The report's ``data``: the span, the sample counts, the candidates without witness."""
    from orbitcal.timescales import utc_s_to_iso

    t = data.t_utc_s
    start, end = utc_s_to_iso([float(t[0]), float(t[-1])])
    held = att.holdout
    return {
        "start": start,
        "end": end,
        "n": int(data.n),
        "n_train": int((~held).sum()),
        "n_holdout": int(held.sum()),
        "holdout": "later time blocks (last 30 % of the span) that no fit saw",
        "candidates_without_witness": sorted(set(EFFECT_NAMES) - {e.name for e in att.effects}),
        "crust_model": data.crust_model,
        "element_age_days": _num(data.element_age_days)
        if data.element_age_days is not None
        else None,
    }


def _provenance(data: DiagnosisData, att: Attribution) -> dict[str, Any]:
    """The tables behind the report (orbitcal.auxdata) and which external-field variant ran."""
    from orbitcal.provenance import result_provenance

    variant = next(
        (str(e.params.get("variant")) for e in att.effects if e.name == "external_field"), None
    )
    if variant is not None and data.b_ext_body_nt is None and data.rc_index_nt is None:
        variant += " (estimated from the data; no RC index for these dates)"
    return result_provenance(
        data.t_utc_s,
        reference_field=data.reference_field,
        rc_index_used=data.rc_index_nt is not None,
        external_field_variant=variant,
    )
