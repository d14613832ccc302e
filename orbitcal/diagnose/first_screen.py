"""The report page's first screen in words: what is wrong, its size, how sure, what to do next.

Every sentence is made from the report's numbers (its JSON), not copied from its longer
statements, so that no line can contradict another:

* **What is wrong**: the verdict in an engineer's words (:data:`EFFECT_TITLES`), its catalogue name
  in brackets.
* **Size**: the verdict's best-measured parameter with its 90 % interval, and what the calibration
  absorbs of its field. "Cannot be separated from the calibration" is said only when the report's
  ``separation`` lists the verdict, which it does only when no parameter is measured
  (:mod:`orbitcal.diagnose.claims`).
* **How sure**: at most three short lines: the probability (``verdict_probability``) when the
  report has one, else the held-out test and how often the verdict wins when the held-out blocks
  are resampled (a count, never a percentage: it is not a probability); the held-out RMS before
  and after (the ``confirmation`` block when present); one caveat (a twin it cannot be told from,
  an unexplained gap).
* **What to do next**: a physical step per selected effect (:func:`physical_step`: for a time-tag
  error, the correction of the time tags with its sign, and the time-tagging chain to check).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "EFFECT_TITLES",
    "NEXT_STEP",
    "NOTHING_FOUND",
    "FirstScreen",
    "first_screen",
    "format_number",
    "param_label",
    "param_unit",
    "physical_step",
    "plain",
]

#: What each effect of the catalogue is, in an engineer's words.
EFFECT_TITLES: dict[str, str] = {
    "none": "no unmodelled effect found",
    "temperature": "a temperature-dependent offset or scale of the sensor",
    "magnetorquer": "magnetorquer fields leaking into the sensor",
    "time_offset": "a time-tag error of the magnetometer samples",
    "external_field": "an external (magnetospheric, ring-current) field the reference lacks",
    "crustal_field": "the crustal field the reference lacks",
    "sun_driven": "a field that follows the Sun (solar-array or heater currents)",
    "nonlinearity": "a nonlinear sensor response",
    "orbit_error": "an orbit (position) error of the element set",
    "parameter_drift": "sensor parameters that changed during the span",
    "field_aligned_currents": "auroral field-aligned currents",
    "attitude_error": "an attitude error",
}

#: What to do, physically, once an effect is found (time_offset's step carries its number:
#: :func:`physical_step`).
NEXT_STEP: dict[str, str] = {
    "temperature": "characterise the sensor's thermal coefficients (offset and scale per °C, on "
    "the ground or over an on-orbit temperature swing); meanwhile calibrate with the temperature "
    "as an input (`--method linear-hk`)",
    "magnetorquer": "add the torquer currents or dipole commands as inputs (`--method "
    "linear-hk`), and check the torquers' dipole signs and the coil-to-sensor distance; or "
    "leave out the samples taken while the torquers fire",
    "time_offset": "correct the magnetometer time tags by the fitted offset and check the "
    "time-tagging chain (sample latch, on-board clock synchronisation, time-code conversion)",
    "external_field": "add the ring-current field to the reference (`--field IGRF-14+RC`), or "
    "calibrate on magnetically quiet days",
    "crustal_field": "add a crustal model to the reference (`--field IGRF-14+LCS-1`)",
    "sun_driven": "find the current that follows the Sun (solar-array strings, heaters) and add "
    "it as an `hk_` input (`--method linear-hk`), or calibrate sunlit and eclipse data apart",
    "nonlinearity": "check the sensor's range and linearity against its ground "
    "characterisation; calibrate with a nonlinear method (`--method lmbp`)",
    "orbit_error": "use fresher elements or GNSS positions (`r_x, r_y, r_z` columns); a drift "
    "faster than drag points to a manoeuvre after the elements' epoch",
    "parameter_drift": "look for what happened when the sensor changed (a power cycle, a "
    "configuration or temperature change) and recalibrate on the data after it (the service's "
    "retraining does)",
    "field_aligned_currents": "nothing is wrong with the sensor (these are real auroral fields): "
    "calibrate on |magnetic latitude| < 60°, or leave the auroral crossings out",
    "attitude_error": "check the attitude solution: the star-tracker-to-magnetometer alignment "
    "and the attitude time tags",
}

#: What to try when nothing in the catalogue explains the residual.
NOTHING_FOUND = (
    "nothing in the catalogue explains the residual: more data (several orbits, a temperature "
    "swing), a prior calibration (`--calibration CAL.json`) or a different attitude (a slew or "
    "tumbling period) would let the diagnosis see more"
)

#: Limit above which "most of its field looks like a change of the 12 parameters" is said.
_MOST = 0.9
#: ... and "part of its field".
_PART = 0.5


def format_number(x: Any, digits: int = 3) -> str:
    """A number to ``digits`` significant digits (thousands grouped, no exponent below 1e6)."""
    if x is None:
        return "–"
    if isinstance(x, bool) or not isinstance(x, int | float):
        return str(x)
    v = float(x)
    if not math.isfinite(v):
        return "–"
    if v == 0.0:
        return "0"
    if 1e-3 <= abs(v) < 1e6:
        mag = math.floor(math.log10(abs(v)))
        decimals = max(digits - 1 - mag, 0)
        text = f"{round(v, decimals):,.{decimals}f}"
    else:
        text = f"{v:.{digits - 1}e}"
    return text.replace("-", "−")


_SNAKE = re.compile(r"\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b")


def plain(text: str) -> str:
    """``text`` with every snake_case word that is not an effect's catalogue name in words
    (``model_left_out_reason`` → ``model left out reason``): the page shows no JSON keys."""
    return _SNAKE.sub(
        lambda m: m.group(0) if m.group(0) in EFFECT_TITLES else m.group(0).replace("_", " "),
        str(text),
    )


# ---- parameters ------------------------------------------------------------------------------

_UNITS: tuple[tuple[str, str], ...] = (
    ("_nt_per_degc", "nT/°C"),
    ("_per_degc", "1/°C"),
    ("_nt_per_day", "nT/day"),
    ("_km_per_day", "km/day"),
    ("_nt_per_am2", "nT/(A·m²)"),
    ("_nt_per_h", "nT/h"),
    ("_mrad", "mrad"),
    ("_nt", "nT"),
    ("_km", "km"),
    ("_s2", "s²"),
    ("_s", "s"),
    ("_ma", "mA"),
)

_LABELS: dict[str, str] = {
    "dt": "time offset dt",
    "dt_squared": "second-order term of the shift (≈ dt²)",
    "rc_model_scale": "scale of the RC-driven field",
    "crust_scale": "scale of the crustal model",
    "crust_low_degrees_scale": "scale of the crust's low degrees",
    "uniform_along_dipole": "uniform field along the dipole axis",
    "uniform_trend": "trend of the uniform field",
    "uniform_recovering": "recovering part of the uniform field",
    "storm_main_phase": "storm main-phase rate",
    "storm_quiet_level": "storm quiet level",
    "storm_recovering": "storm recovering part",
    "along_track": "along-track position error",
    "along_track_offset": "along-track position offset",
    "along_track_rate": "along-track drift",
    "radial": "radial position error",
}


def param_unit(name: str) -> str:
    """The unit a parameter's name ends with ("" when none)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def param_label(name: str) -> str:
    """A parameter of the catalogue in words, without its unit (``dt_s`` → ``time offset dt``)."""
    m = re.fullmatch(r"coupling_([xyz])([xyz])_nt_per_am2", name)
    if m:
        return f"coupling of the {m.group(2)} torquer into sensor {m.group(1)}"
    m = re.fullmatch(r"sun_([xyz])_to_([xyz])_nt", name)
    if m:
        return f"Sun along body {m.group(1)} into sensor {m.group(2)}"
    m = re.fullmatch(r"(offset|scale)_([xyz])(?:_nt)?_per_degc", name)
    if m:
        return f"thermal {m.group(1)} coefficient, {m.group(2)}"
    stem = name
    for suffix, _ in _UNITS:
        if name.endswith(suffix):
            stem = name[: -len(suffix)]
            break
    if stem in _LABELS:
        return _LABELS[stem]
    m = re.fullmatch(r"(.*)_([xyz])", stem)
    if m and m.group(1) in _LABELS:
        return f"{_LABELS[m.group(1)]}, {m.group(2)}"
    return stem.replace("_", " ")


# ---- the screen --------------------------------------------------------------------------------


@dataclass
class FirstScreen:
    """The first screen's claims, each a sentence (``separable``: None for a verdict of none)."""

    verdict: str
    headline: str
    size: str | None
    separable: bool | None
    how_sure: list[str]
    next_steps: list[str] = field(default_factory=list)


def _num(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    return float(x) if math.isfinite(float(x)) else None


def _by_name(report: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    return {str(e.get("name")): e for e in report.get("effects") or [] if isinstance(e, dict)}


def _age(report: Mapping[str, Any]) -> float | None:
    data = report.get("data")
    return _num(data.get("element_age_days")) if isinstance(data, dict) else None


def _twins(report: Mapping[str, Any], entry: Mapping[str, Any]) -> list[str]:
    names = [str(t) for t in (entry.get("params") or {}).get("indistinguishable_from") or []]
    for c in report.get("confounded_with") or []:
        if isinstance(c, dict) and c.get("name") and str(c["name"]) not in names:
            names.append(str(c["name"]))
    return names


def _value_text(entry: Mapping[str, Any], name: str) -> str:
    """``time offset dt = −0.498 s (90 %: −0.499 … −0.496 s)``."""
    unit = param_unit(name)
    u = f" {unit}" if unit else ""
    text = f"{param_label(name)} = {format_number((entry.get('params') or {}).get(name))}{u}"
    iv = (entry.get("param_intervals_90") or {}).get(name)
    if isinstance(iv, list | tuple) and len(iv) == 2 and None not in iv:
        text += f" (90 %: {format_number(iv[0])} … {format_number(iv[1])}{u})"
    return text


def _absorbed_clause(entry: Mapping[str, Any]) -> str:
    a = _num(entry.get("absorbed_by_calibration_fraction"))
    if a is None or a < _PART:
        return ""
    share = "most" if a >= _MOST else "part"
    return (
        f"; {share} of its field ({a:.1%}) looks like a change of the 12 calibration parameters, "
        "and the rest measures its size"
    )


def _size(report: Mapping[str, Any], verdict: str) -> tuple[str | None, bool | None]:
    """The size sentence and whether the report calls the verdict separable."""
    from orbitcal.diagnose.claims import measured_parameters, size_measured

    if verdict == "none":
        return None, None
    entry = _by_name(report).get(verdict)
    separation = {
        str(s.get("effect")): s for s in report.get("separation") or [] if isinstance(s, dict)
    }
    separable = verdict not in separation
    if entry is None:
        return None, separable
    numeric = [k for k, v in (entry.get("params") or {}).items() if _num(v) is not None]
    measured = measured_parameters(
        verdict,
        entry.get("params") or {},
        entry.get("param_intervals_90") or {},
        age_days=_age(report),
    )
    if measured and size_measured(entry, age_days=_age(report)):
        return _value_text(entry, measured[0]) + _absorbed_clause(entry), True
    if not separable:
        s = separation[verdict]
        a = _num(s.get("absorbed_fraction"))
        share = f"{a:.1%} of its field" if a is not None else "its field"
        return (
            f"not measured on this span: {share} looks like a change of the 12 calibration "
            "parameters and no parameter's 90 % interval pins it down; its size cannot be "
            f"separated from the calibration here (to measure it: {s.get('would_separate')})",
            False,
        )
    if numeric:
        return (
            _value_text(entry, numeric[0])
            + "; not pinned down: no parameter's 90 % interval is tight and clear of zero",
            True,
        )
    return (
        f"held-out RMS {format_number(entry.get('holdout_rms_before_nt'))} → "
        f"{format_number(entry.get('holdout_rms_after_nt'))} nT with it (its model has no "
        "parameter to state)",
        True,
    )


def _probability_line(report: Mapping[str, Any], verdict: str) -> str:
    from orbitcal.diagnose.claims import resample_words

    vp = _num(report.get("verdict_probability"))
    if vp is not None:
        what = "no effect is present" if verdict == "none" else f"{verdict} is present"
        return f"Probability {100.0 * vp:.0f} % that {what}."
    if verdict == "none":
        return "No candidate shrinks the held-out residual significantly."
    entry = _by_name(report).get(verdict) or {}
    p = _num(entry.get("p_value"))
    text = "Named by the held-out test" + (f" (p = {format_number(p, 2)})" if p is not None else "")
    conf = _num(report.get("verdict_confidence"))
    if conf is not None:
        text += f"; it wins in {resample_words(conf)} of the held-out blocks"
    return text + "."


def _shrink_words(confirmation: Mapping[str, Any]) -> str:
    """``; shrink S (90 % interval A-B ...)`` when the confirmation carries its interval."""
    shrink = _num(confirmation.get("shrink"))
    interval = confirmation.get("shrink_interval_90")
    if shrink is None or not isinstance(interval, list) or len(interval) != 2:
        return ""
    lo, hi = (_num(v) for v in interval)
    if lo is None or hi is None:
        return ""
    return (
        f"; shrink {format_number(shrink, 3)}× (90 % interval {format_number(lo, 3)}–"
        f"{format_number(hi, 3)}, a bootstrap over orbit-long blocks of the final block)"
    )


def _rms_line(report: Mapping[str, Any], verdict: str) -> str:
    model = report.get("model") or {}
    by_events = (model.get("event_confirmations") or {}).get(verdict)
    if isinstance(by_events, dict) and verdict in (model.get("named") or []):
        p = _num(by_events.get("p_value"))
        # amplitudes that change from event to event: no fit on other data forecasts them
        return (
            "Within the final block's events, each fitted on part of itself: RMS "
            f"{format_number(by_events.get('holdout_rms_before_nt'))} → "
            f"{format_number(by_events.get('holdout_rms_after_nt'))} nT"
            + (f" (p = {format_number(p, 2)})" if p is not None else "")
            + "."
        )
    confirmation = report.get("confirmation")
    if isinstance(confirmation, dict) and _num(confirmation.get("holdout_rms_before_nt")):
        p = _num(confirmation.get("p_value"))
        return (
            "On a final block no selection used: held-out RMS "
            f"{format_number(confirmation.get('holdout_rms_before_nt'))} → "
            f"{format_number(confirmation.get('holdout_rms_after_nt'))} nT"
            + (f" (p = {format_number(p, 2)})" if p is not None else "")
            + _shrink_words(confirmation)
            + "."
        )
    base = report.get("baseline") or {}
    final = report.get("final") or {}
    gap = report.get("gap") or {}
    floor = _num(gap.get("noise_floor_nt"))
    noise = f" (noise floor {format_number(floor)} nT)" if floor is not None else ""
    if verdict == "none":
        return f"Held-out RMS {format_number(base.get('holdout_rms_nt'))} nT{noise}."
    return (
        f"Held-out RMS {format_number(base.get('holdout_rms_nt'))} → "
        f"{format_number(final.get('holdout_rms_nt'))} nT with the selected effects{noise}."
    )


def _caveat(report: Mapping[str, Any], verdict: str) -> str | None:
    gap = report.get("gap") or {}
    if verdict == "none" and not gap.get("unexplained"):
        whole = [str(n) for n in gap.get("absorbed_by_calibration") or []]
        if whole:
            return (
                f"The calibration would take up {', '.join(whole[:2])} whole on this span: if "
                "present, it cannot be seen here."
            )
        return None
    if verdict == "none":
        if gap.get("unexplained"):
            inseparable = [str(n) for n in gap.get("inseparable") or []]
            if inseparable:
                return (
                    f"An unexplained gap of {format_number(gap.get('times_noise'))} × the noise "
                    f"floor: {', '.join(inseparable)} would shrink it, but the calibration on "
                    "this span cannot tell whether it is there."
                )
            return (
                f"An unexplained gap: {format_number(gap.get('times_noise'))} × the noise floor, "
                "and no candidate explains it."
            )
        return None
    entry = _by_name(report).get(verdict) or {}
    twins = _twins(report, entry)
    if twins:
        return f"On these data it cannot be told apart from {', '.join(twins)}."
    conf = _num(report.get("verdict_confidence"))
    if conf is not None and conf < 0.8 and report.get("verdict_probability") is None:
        return "Tentative: another candidate wins in some resamples of the held-out blocks."
    if gap.get("unexplained"):
        return (
            f"A gap of {format_number(gap.get('times_noise'))} × the noise floor remains beside "
            "the selected effects."
        )
    return None


def physical_step(name: str, entry: Mapping[str, Any] | None = None) -> str:
    """What to do about effect ``name`` (its report entry gives the numbers a step needs)."""
    params = (entry or {}).get("params") or {}
    dt = _num(params.get("dt_s"))
    if name == "time_offset" and dt is not None:
        late = "late" if dt < 0 else "early"
        return (
            f"add {format_number(dt)} s to the magnetometer time tags (they run "
            f"{format_number(abs(dt))} s {late}); check the time-tagging chain (sample latch, "
            "on-board clock synchronisation, time-code conversion), then recalibrate"
        )
    return NEXT_STEP.get(name, "more data")


def _next_steps(report: Mapping[str, Any], verdict: str) -> list[str]:
    from orbitcal.diagnose.claims import size_measured
    from orbitcal.diagnose.report import SEPARATING_DATA

    by_name = _by_name(report)
    selected = [e for e in by_name.values() if e.get("significant")]
    if verdict != "none" and verdict in by_name and by_name[verdict] not in selected:
        selected.insert(0, by_name[verdict])
    separation = {
        str(s.get("effect")): s for s in report.get("separation") or [] if isinstance(s, dict)
    }
    steps = []
    for e in selected:
        name = str(e.get("name"))
        step = f"{name}: {physical_step(name, e)}"
        if name in separation and not size_measured(e, age_days=_age(report)):
            step += f"; to measure its size: {separation[name].get('would_separate')}"
        steps.append(step)
        twins = _twins(report, e) if name == verdict else []
        if twins:
            hints = "; ".join(f"{SEPARATING_DATA.get(t, 'more data')} (for {t})" for t in twins)
            steps.append(f"to tell {name} from {', '.join(twins)}: {hints}")
    gap = report.get("gap") or {}
    if not steps and verdict == "none" and gap and not gap.get("unexplained"):
        steps.append(
            "nothing to correct: what the calibration leaves on the held-out blocks is at the "
            "noise floor; keep the calibration and watch its residual on new data"
        )
    if not steps:
        steps.append(NOTHING_FOUND)
    return steps


def headline(report: Mapping[str, Any]) -> str:
    """What is wrong, in words, with the catalogue name."""
    verdict = str(report.get("verdict", "none"))
    if verdict == "none":
        return "No unmodelled effect found"
    title = EFFECT_TITLES.get(verdict, verdict)
    return f"{title[0].upper()}{title[1:]} ({verdict})"


def first_screen(report: Mapping[str, Any]) -> FirstScreen:
    """The first screen's claims of a section-5 report (its JSON)."""
    verdict = str(report.get("verdict", "none"))
    size, separable = _size(report, verdict)
    lines = [_probability_line(report, verdict), _rms_line(report, verdict)]
    caveat = _caveat(report, verdict)
    if caveat:
        lines.append(caveat)
    return FirstScreen(
        verdict=verdict,
        headline=headline(report),
        size=size,
        separable=separable,
        how_sure=lines,
        next_steps=_next_steps(report, verdict),
    )


def effect_names_in(text: str) -> Sequence[str]:
    """The catalogue names ``text`` mentions (for checks of the page's claims)."""
    return [n for n in EFFECT_TITLES if re.search(rf"\b{n}\b", text)]
