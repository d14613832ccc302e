"""The diagnosis report as one self-contained HTML page, drawn from the report's JSON alone.

The page answers what an attitude and orbit control engineer asks first, on its first screen:
what is wrong (the verdict), where (the where-sentence), how sure (status, confidence, held-out
RMS before and after), what to do next, and the evidence (the residual before and after the
selected effects against each effect's driver, ``report["evidence"]``). The full JSON is one
click away (a download link); tables of every candidate, where the residual lies and the tables
behind it follow below. The layout is the Jinja2 template ``report_template.html`` beside this
module; this module turns the JSON into the template's values (numbers to three significant
digits, intervals that only reach a parameter's physical range flagged as bound-limited).

Because only the JSON is read, ``orbitcal diagnose --html`` and the service's
``/diagnosis/report.html`` give the same page for the same report; keys added to the report
later are tolerated (shown under "Other sections").
"""

from __future__ import annotations

import base64
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

from orbitcal.diagnose.first_screen import (
    EFFECT_TITLES,
    NEXT_STEP,
    NOTHING_FOUND,
    first_screen,
    format_number,
    param_label,
    plain,
)

__all__ = [
    "EFFECT_TITLES",
    "NEXT_STEP",
    "NOTHING_FOUND",
    "first_screen_html",
    "format_number",
    "report_html",
]

_AXES = "xyz"


# ---- parameters ----------------------------------------------------------------------------


def _param_meaning(name: str) -> str:
    """Plain words for a catalogue parameter name (units are in the names)."""
    m = re.fullmatch(r"coupling_([xyz])([xyz])_nt_per_am2", name)
    if m:
        return f"sensor {m.group(1)} axis per A·m² of the {m.group(2)} torquer [nT/(A·m²)]"
    m = re.fullmatch(r"sun_([xyz])_to_([xyz])_nt", name)
    if m:
        return f"sensor {m.group(2)} axis per unit Sun direction along body {m.group(1)} [nT]"
    unit = ""
    for suffix, text in (
        ("_nt_per_degc", "nT/°C"),
        ("_nt_per_day", "nT/day"),
        ("_nt_per_am2", "nT/(A·m²)"),
        ("_mrad", "mrad"),
        ("_nt", "nT"),
        ("_km", "km"),
        ("_s2", "s²"),
        ("_s", "s"),
    ):
        if name.endswith(suffix):
            unit = text
            break
    return f"[{unit}]" if unit else ""


def _bounds(effect: str, name: str, age_days: float | None) -> tuple[float, float] | None:
    """The physical range of ``effect``'s parameter ``name`` for an element set ``age_days``
    from the data (None when unbounded)."""
    from orbitcal.diagnose.effects import effect_param_range

    r = effect_param_range(effect, name, age_days)
    if not (math.isfinite(r.lower) and math.isfinite(r.upper)):
        return None
    return r.lower, r.upper


def _flagged(effect: dict[str, Any]) -> set[str]:
    """Parameter names the report itself marks as bound-limited (a list or a dict of names)."""
    marked = effect.get("bound_limited")
    if isinstance(marked, dict):
        return {str(k) for k, v in marked.items() if v}
    if isinstance(marked, list | tuple):
        return {str(k) for k in marked}
    return set()


@dataclass
class ParamRow:
    name: str
    meaning: str
    value: str
    interval: str
    bound_limited: bool


def _is_bound(x: float, edge: float) -> bool:
    return abs(x - edge) <= 1e-3 * max(abs(edge), 1.0)


def _param_rows(effect: dict[str, Any], age_days: float | None = None) -> list[ParamRow]:
    intervals = effect.get("param_intervals_90") or {}
    marked = _flagged(effect)
    rows = []
    for name, value in (effect.get("params") or {}).items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        iv = intervals.get(name)
        limited = name in marked
        text = "–"
        if isinstance(iv, list | tuple) and len(iv) == 2 and None not in iv:
            lo, hi = float(iv[0]), float(iv[1])
            bounds = _bounds(str(effect.get("name")), name, age_days)
            if bounds is not None and (_is_bound(lo, bounds[0]) or _is_bound(hi, bounds[1])):
                limited = True
            text = f"{format_number(lo)} … {format_number(hi)}"
            if limited:
                edges = bounds or (lo, hi)
                text = (
                    f"bound-limited: reaches the physical range "
                    f"[{format_number(edges[0])}, {format_number(edges[1])}], not measured"
                )
        elif limited:
            text = "bound-limited, not measured"
        rows.append(
            ParamRow(param_label(name), _param_meaning(name), format_number(value), text, limited)
        )
    return rows


def _notes(effect: dict[str, Any]) -> list[str]:
    out = []
    params = effect.get("params") or {}
    for key in ("variant",):
        if isinstance(params.get(key), str):
            out.append(f"model variant: {params[key].replace('_', ' ')}")
    twins = params.get("indistinguishable_from")
    if twins:
        out.append("cannot be told apart on these data from: " + ", ".join(map(str, twins)))
    if effect.get("implausible_reason"):
        out.append(f"implausible: {effect['implausible_reason']}")
    for key in ("absorbed_reason", "remark"):
        if isinstance(effect.get(key), str):
            out.append(effect[key])
    if str(effect.get("name", "")).startswith("magnetorquer") or any(
        str(k).startswith("coupling_") for k in params
    ):
        out.append("couplings in sensor axes (rows) per body-axis torquer dipole (columns)")
    return out


@dataclass
class EffectView:
    name: str
    title: str
    status: str
    selected: bool
    before: str
    after: str
    shrink: str
    shrink_interval: str
    p_value: str
    params: list[ParamRow]
    notes: list[str]
    all_bound_limited: bool
    probability: str = ""


def _probability(p: Any) -> str:
    """An effect's ``probability`` (0-1, calibrated; CONTRACT section 5) as a percentage, or ""
    when the report has none."""
    if isinstance(p, bool) or not isinstance(p, int | float) or not math.isfinite(float(p)):
        return ""
    return f"{100.0 * float(p):.0f} %"


def _effect_view(e: dict[str, Any], age_days: float | None = None) -> EffectView:
    rows = _param_rows(e, age_days)
    iv = e.get("shrink_interval_90")
    return EffectView(
        name=str(e.get("name")),
        title=EFFECT_TITLES.get(str(e.get("name")), str(e.get("name"))),
        status=str(e.get("status") or ("selected" if e.get("significant") else "not selected")),
        selected=bool(e.get("significant")),
        before=format_number(e.get("holdout_rms_before_nt")),
        after=format_number(e.get("holdout_rms_after_nt")),
        shrink=format_number(e.get("shrink")),
        shrink_interval=(
            f"{format_number(iv[0])} … {format_number(iv[1])}"
            if isinstance(iv, list | tuple) and len(iv) == 2
            else "–"
        ),
        p_value=format_number(e.get("p_value"), 2),
        params=rows,
        notes=[plain(n) for n in _notes(e)],
        all_bound_limited=bool(rows) and all(r.bound_limited for r in rows),
        probability=_probability(e.get("probability")),
    )


# ---- the first screen ------------------------------------------------------------------------


def _where_sentence(where: dict[str, Any] | None) -> str:
    if not isinstance(where, dict):
        return "not located (the report has no where-analysis)"
    conc = str(where.get("concentration", "everywhere"))
    m = re.fullmatch(r"\|mlat\| ([\d.]+)-([\d.]+) deg", conc)
    if m:
        text = f"concentrated at |magnetic latitude| {m.group(1)}–{m.group(2)}°"
    elif conc in ("sunlit", "eclipse"):
        text = "concentrated in sunlight" if conc == "sunlit" else "concentrated in eclipse"
    elif conc == "everywhere":
        text = "spread over the whole orbit (no latitude band or sunlit/eclipse condition holds a "
        text += "clear excess)"
    else:
        text = f"concentrated at {conc}"
    axes = where.get("axis_rms_nt")
    if isinstance(axes, list) and len(axes) == 3 and all(isinstance(a, int | float) for a in axes):
        k = max(range(3), key=lambda i: float(axes[i]))
        per_axis = ", ".join(f"{_AXES[i]} {format_number(axes[i])}" for i in range(3))
        text += f"; per sensor axis {per_axis} nT held-out RMS (largest on {_AXES[k]})"
    return text


def _statement(value: Any) -> str | None:
    """A one-line statement of a report section added later (e.g. ``gap``), if it has one."""
    if isinstance(value, str):
        return value
    if isinstance(value, dict):
        for key in ("statement", "summary", "text"):
            if isinstance(value.get(key), str):
                return str(value[key])
    return None


# ---- figures ---------------------------------------------------------------------------------


@dataclass
class Figure:
    """One plot: an inline SVG (no image library, no external file)."""

    title: str
    caption: str
    svg: str


_W, _H = 470.0, 250.0
_LEFT, _RIGHT, _TOP, _BOTTOM = 56.0, 12.0, 34.0, 40.0


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    if not hi > lo:
        return [lo]
    raw = (hi - lo) / n
    step = 10.0 ** math.floor(math.log10(raw))
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if raw <= m * step:
            step *= m
            break
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step + 1e-9) + 1)]


def _tick(v: float) -> str:
    """A tick label: the shortest exact text of a round number."""
    return f"{round(v, 10):,.10g}".replace("-", "−")


def _esc(text: str) -> str:
    import markupsafe

    return str(markupsafe.escape(text))


def _line_svg(
    x: list[float],
    series: Sequence[tuple[str, str, Sequence[float | None]]],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    shade_from: float | None = None,
    xticklabels: list[str] | None = None,
    y_from_zero: bool = True,
) -> str:
    """A line plot as SVG: ``series`` are (label, colour, y) over the same ``x``."""
    ys = [v for _, _, y in series for v in y if v is not None and math.isfinite(v)]
    if not x or not ys:
        return ""
    x0, x1 = min(x), max(x)
    if x1 == x0:
        x0, x1 = x0 - 0.5, x1 + 0.5
    y0 = 0.0 if y_from_zero else min(ys)
    y1 = max(ys)
    if y1 == y0:
        y1 = y0 + 1.0
    y1 += 0.05 * (y1 - y0)
    pw, ph = _W - _LEFT - _RIGHT, _H - _TOP - _BOTTOM

    def px(v: float) -> float:
        return _LEFT + (v - x0) / (x1 - x0) * pw

    def py(v: float) -> float:
        return _TOP + ph - (v - y0) / (y1 - y0) * ph

    out = [
        f'<svg class="plot" viewBox="0 0 {_W:g} {_H:g}" width="{_W:g}" height="{_H:g}" '
        f'role="img" aria-label="{_esc(title)}" xmlns="http://www.w3.org/2000/svg">',
        f'<text x="{_LEFT:g}" y="13" class="title">{_esc(title)}</text>',
    ]
    if shade_from is not None and x0 <= shade_from <= x1:
        out.append(
            f'<rect x="{px(shade_from):.1f}" y="{_TOP:g}" width="{px(x1) - px(shade_from):.1f}" '
            f'height="{ph:g}" fill="#eee"/><text x="{px(x1) - 4:.1f}" y="{_TOP + 12:g}" '
            'text-anchor="end" class="tick">held out</text>'
        )
    for t in _ticks(y0, y1):
        out.append(
            f'<line x1="{_LEFT:g}" x2="{_LEFT + pw:g}" y1="{py(t):.1f}" y2="{py(t):.1f}" '
            f'stroke="#e6e6e6"/><text x="{_LEFT - 4:g}" y="{py(t) + 3:.1f}" text-anchor="end" '
            f'class="tick">{_esc(_tick(t))}</text>'
        )
    if xticklabels is not None:
        xt = [(v, lab) for v, lab in zip(x, xticklabels, strict=True)]
    else:
        xt = [(t, _tick(t)) for t in _ticks(x0, x1, 6)]
    for v, lab in xt:
        # a label at an edge of the plot is anchored inside it ("eclipse" was cut to "eclips")
        anchor = "start" if px(v) - _LEFT < 20 else "end" if _LEFT + pw - px(v) < 20 else "middle"
        out.append(
            f'<text x="{px(v):.1f}" y="{_TOP + ph + 14:g}" text-anchor="{anchor}" '
            f'class="tick">{_esc(lab)}</text>'
        )
    out.append(
        f'<rect x="{_LEFT:g}" y="{_TOP:g}" width="{pw:g}" height="{ph:g}" fill="none" '
        'stroke="#999"/>'
        f'<text x="{_LEFT + pw / 2:g}" y="{_H - 6:g}" text-anchor="middle" class="label">'
        f"{_esc(xlabel)}</text>"
        f'<text transform="translate(12 {_TOP + ph / 2:g}) rotate(-90)" text-anchor="middle" '
        f'class="label">{_esc(ylabel)}</text>'
    )
    for k, (label, colour, y) in enumerate(series):
        pts = [
            f"{px(a):.1f},{py(b):.1f}"
            for a, b in zip(x, y, strict=True)
            if b is not None and math.isfinite(b)
        ]
        out.append(
            f'<polyline fill="none" stroke="{colour}" stroke-width="1.6" points="{" ".join(pts)}"/>'
        )
        out.extend(
            f'<circle cx="{p.split(",")[0]}" cy="{p.split(",")[1]}" r="2" fill="{colour}"/>'
            for p in pts
        )
        lx = _LEFT + 150 * k
        out.append(
            f'<line x1="{lx:g}" x2="{lx + 16:g}" y1="{_TOP - 9:g}" y2="{_TOP - 9:g}" '
            f'stroke="{colour}" stroke-width="2"/><text x="{lx + 20:g}" y="{_TOP - 6:g}" '
            f'class="tick">{_esc(label)}</text>'
        )
    out.append("</svg>")
    return "".join(out)


def _evidence_figure(curve: dict[str, Any]) -> Figure | None:
    x = curve.get("x") or []
    before = curve.get("rms_before_nt") or []
    after = curve.get("rms_after_nt") or []
    if not x or len(x) != len(before) or len(x) != len(after):
        return None
    effects = [str(e) for e in curve.get("effects") or []]
    label = str(curve.get("label", curve.get("driver", "")))
    driver = str(curve.get("name") or label.split(" [")[0])
    title = f"Residual vs {driver}" + (f" ({', '.join(effects)})" if effects else "")
    held = curve.get("held_out_from")
    svg = _line_svg(
        [float(v) for v in x],
        [("calibration alone", "#c0392b", before), ("with the selected effects", "#2471a3", after)],
        title=title,
        xlabel=label,
        ylabel="residual RMS [nT]",
        shade_from=float(held) if isinstance(held, int | float) else None,
    )
    caption = f"Per-component RMS in {len(x)} bins of {sum(curve.get('n') or [0])} samples" + (
        f"; the driver of {', '.join(effects)}" if effects else ""
    )
    return Figure(title, caption, svg) if svg else None


def _shrink_figure(report: dict[str, Any]) -> Figure | None:
    eff = [e for e in report.get("effects", []) if isinstance(e, dict)]
    if not eff:
        return None
    shr = [float(e.get("shrink") or 0.0) for e in eff]
    top = max(max(shr), 1.0) * 1.05
    row, left, width = 18.0, 170.0, 330.0
    height = row * len(eff) + 30
    out = [
        f'<svg class="plot" viewBox="0 0 {left + width + 60:g} {height:g}" '
        f'width="{left + width + 60:g}" height="{height:g}" role="img" '
        'aria-label="shrink per candidate" xmlns="http://www.w3.org/2000/svg">'
    ]
    for k, (e, v) in enumerate(zip(eff, shr, strict=True)):
        y = 6 + k * row
        colour = "#c0392b" if e.get("significant") else "#aaa"
        out.append(
            f'<text x="{left - 6:g}" y="{y + 12:g}" text-anchor="end" class="tick">'
            f"{_esc(str(e.get('name')))}</text>"
            f'<rect x="{left:g}" y="{y + 2:g}" width="{width * v / top:.1f}" height="{row - 5:g}" '
            f'fill="{colour}"/><text x="{left + width * v / top + 4:.1f}" y="{y + 12:g}" '
            f'class="tick">{_esc(format_number(v))}</text>'
        )
    one = left + width / top
    out.append(
        f'<line x1="{one:.1f}" x2="{one:.1f}" y1="2" y2="{height - 22:g}" stroke="#000"/>'
        f'<text x="{left + width / 2:g}" y="{height - 6:g}" text-anchor="middle" class="label">'
        "held-out shrink (RMS before / after); 1 = no gain</text></svg>"
    )
    return Figure(
        "Shrink per candidate", "red: selected; each candidate fitted alone", "".join(out)
    )


def _split_figure(report: dict[str, Any]) -> Figure | None:
    splits = [s for s in report.get("split_fits") or [] if isinstance(s, dict)]
    svgs = []
    for s in splits:
        off = [list(map(float, row)) for row in s.get("offsets_nt") or []]
        if len(off) < 2:
            continue
        mean = [sum(r[k] for r in off) / len(off) for k in range(3)]
        series = [
            (f"{_AXES[k]} axis", colour, [r[k] - mean[k] for r in off])
            for k, colour in enumerate(("#c0392b", "#27ae60", "#2471a3"))
        ]
        svgs.append(
            _line_svg(
                list(map(float, range(len(off)))),
                series,
                title=f"{plain(str(s.get('name')))} (z = {format_number(s.get('z'), 2)})",
                xlabel="part of the data",
                ylabel="offset − mean [nT]",
                xticklabels=[str(v) for v in s.get("labels") or range(len(off))],
                y_from_zero=False,
            )
        )
    if not svgs:
        return None
    return Figure(
        "Split fits",
        "offsets fitted on parts of the data apart (sunlit/eclipse, time blocks)",
        "".join(svgs),
    )


# ---- where, provenance, other sections ---------------------------------------------------------


def _where_rows(where: dict[str, Any] | None, final: dict[str, Any] | None) -> list[list[str]]:
    rows: list[list[str]] = []
    if not isinstance(where, dict):
        return rows
    after = {}
    if isinstance(final, dict):
        after = {
            tuple(b.get("band_deg", [])): b
            for b in final.get("magnetic_latitude", [])
            if isinstance(b, dict)
        }
    for b in where.get("magnetic_latitude", []):
        if not isinstance(b, dict):
            continue
        lo, hi = (b.get("band_deg") or [None, None])[:2]
        a = after.get(tuple(b.get("band_deg", [])), {})
        rows.append(
            [
                f"|mlat| {_tick(float(lo or 0))}–{_tick(float(hi or 0))}°",
                str(b.get("n", "")),
                format_number(b.get("rms_nt")),
                format_number(a.get("rms_nt")),
                format_number(b.get("scalar_rms_nt")),
                format_number(b.get("perpendicular_rms_nt")),
            ]
        )
    se = where.get("sunlit_eclipse")
    se_after = (final or {}).get("sunlit_eclipse") if isinstance(final, dict) else None
    if isinstance(se, dict):
        for key in ("sunlit", "eclipse"):
            st = se.get(key) or {}
            a = (se_after or {}).get(key) or {}
            rows.append(
                [
                    key,
                    str(st.get("n", "")),
                    format_number(st.get("rms_nt")),
                    format_number(a.get("rms_nt")),
                    format_number(st.get("scalar_rms_nt")),
                    format_number(st.get("perpendicular_rms_nt")),
                ]
            )
    return rows


def _provenance_rows(prov: dict[str, Any] | None) -> list[list[str]]:
    if not isinstance(prov, dict):
        return []
    rows = []
    for name, t in (prov.get("tables") or {}).items():
        if isinstance(t, dict):
            rows.append(
                [
                    plain(str(name)),
                    str(t.get("format") or t.get("file") or ""),
                    str(t.get("origin") or ""),
                    str(t.get("status") or ""),
                ]
            )
    return rows


#: Report keys this page shows in its own sections.
_KNOWN = {
    "baseline",
    "verdict",
    "verdict_confidence",
    "verdict_confidence_of",
    "verdict_status",
    "verdict_probability",
    "confirmation",
    "confounded_with",
    "separable",
    "separation",
    "effects",
    "where",
    "final",
    "split_fits",
    "data",
    "learned",
    "provenance",
    "evidence",
}


#: Titles of the report's sections that carry a statement (shown below the first screen).
_SECTION_TITLES = {
    "gap": "What is left",
    "honesty": "The claims checked on the held-out data",
}


@dataclass
class Page:
    title: str
    verdict: str
    headline: str
    where_sentence: str
    where_after: str | None
    size: str | None
    separable: bool | None
    how_sure: list[str]
    statements: list[tuple[str, str]]
    next_steps: list[str]
    evidence: list[Figure]
    more_figures: list[Figure]
    selected: list[EffectView]
    others: list[EffectView]
    where_rows: list[list[str]]
    provenance_rows: list[list[str]]
    warnings: list[str]
    data_line: str
    extra_sections: list[str] = field(default_factory=list)
    json_href: str = ""


@cache
def _template() -> Any:
    import jinja2

    text = resources.files("orbitcal.diagnose").joinpath("report_template.html").read_text("utf-8")
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined)
    env.filters["code"] = _code
    return env.from_string(text)


def _code(text: str) -> Any:
    """Backquoted words as <code> (the rest escaped)."""
    import markupsafe

    parts = str(text).split("`")
    out = markupsafe.Markup("")
    for k, p in enumerate(parts):
        out += markupsafe.Markup("<code>{}</code>").format(p) if k % 2 else markupsafe.escape(p)
    return out


def _section(report: dict[str, Any], key: str) -> dict[str, Any]:
    value = report.get(key)
    return value if isinstance(value, dict) else {}


def _page(report: dict[str, Any], title: str) -> Page:
    age = _section(report, "data").get("element_age_days")
    age_days = float(age) if isinstance(age, int | float) and not isinstance(age, bool) else None
    effects = [_effect_view(e, age_days) for e in report.get("effects", []) if isinstance(e, dict)]
    final = _section(report, "final")
    where_final = final.get("where")
    figures = [
        f
        for f in (_evidence_figure(c) for c in report.get("evidence") or [] if isinstance(c, dict))
        if f is not None
    ]
    more = [f for f in (_shrink_figure(report), _split_figure(report)) if f is not None]
    statements = []
    extra = []
    for key, value in report.items():
        if key in _KNOWN:
            continue
        text = _statement(value)
        heading = _SECTION_TITLES.get(key, key.replace("_", " ").capitalize())
        if text is not None:
            statements.append((heading, plain(text)))
        else:
            extra.append(heading)
    data = _section(report, "data")
    base = _section(report, "baseline")
    start, end = (str(data.get(k, "?"))[:19].replace("T", " ") for k in ("start", "end"))
    data_line = (
        f"{data.get('n', '?')} samples, {start} to {end} UTC; "
        f"fitted on {data.get('n_train', '?')}, judged on {data.get('n_holdout', '?')} "
        f"({data.get('holdout', 'later time blocks')}); reference field "
        f"{base.get('reference_field', '?')}, baseline {base.get('method', '?')}"
    )
    if base.get("calibration_prior"):
        data_line += "; the calibration in service as a prior"
    prov = _section(report, "provenance")
    payload = json.dumps(report, indent=1, default=str).encode("utf-8")
    screen = first_screen(report)
    return Page(
        title=title,
        verdict=screen.verdict,
        headline=screen.headline,
        where_sentence=_where_sentence(report.get("where")),
        where_after=_where_sentence(where_final) if isinstance(where_final, dict) else None,
        size=screen.size,
        separable=screen.separable,
        how_sure=screen.how_sure,
        statements=statements,
        next_steps=screen.next_steps,
        evidence=figures,
        more_figures=more,
        selected=[e for e in effects if e.selected],
        others=[e for e in effects if not e.selected],
        where_rows=_where_rows(report.get("where"), where_final),
        provenance_rows=_provenance_rows(prov),
        warnings=[str(w) for w in prov.get("warnings") or []],
        data_line=data_line,
        extra_sections=extra,
        json_href="data:application/json;base64," + base64.b64encode(payload).decode("ascii"),
    )


def report_html(report: dict[str, Any], *, title: str = "orbitcal diagnosis") -> str:
    """A self-contained HTML page of a section-5 report (plots as inline SVG, the JSON as a
    download link), drawn from the report's JSON alone.

    Parameters
    ----------
    report : dict
        The report as ``orbitcal diagnose --out`` writes it or the service answers it; keys this
        page does not know are shown at its end.
    title : str, keyword-only
        The page's title (e.g. naming the spacecraft).
    """
    return str(_template().render(page=_page(report, title)))


def first_screen_html(report: Mapping[str, Any]) -> str:
    """The first screen's claims as an HTML fragment (a notebook's view of a report): what is
    wrong, its size, how sure and what to do next, as :func:`report_html` states them."""
    screen = first_screen(report)
    rows = [("What is wrong", _esc(screen.headline))]
    if screen.size:
        rows.append(("Size", str(_code(screen.size))))
    rows.append(("How sure", "<br>".join(_esc(line) for line in screen.how_sure)))
    steps = "".join(f"<li>{_code(step)}</li>" for step in screen.next_steps)
    rows.append(("What to do next", f'<ul style="margin:0;padding-left:1.1em">{steps}</ul>'))
    body = "".join(
        f'<tr><th style="text-align:left;vertical-align:top">{k}</th>'
        f'<td style="text-align:left">{v}</td></tr>'
        for k, v in rows
    )
    return f'<table class="orbitcal-report">{body}</table>'
