"""The diagnosis report: CONTRACT section-5 JSON and a self-contained HTML page.

JSON keys of section 5 are written exactly: ``baseline {method, holdout_rms_nt}``, ``verdict``,
``effects [{name, significant, holdout_rms_before_nt, holdout_rms_after_nt, shrink, params}]``
(ranked, most explanatory first) and ``where {axis_rms_nt, ...}``. Supporting sections are added
around them (``final``, ``split_fits``, ``learned``, ``data``).

The HTML embeds matplotlib PNGs as base64 (shrink per effect, residual map along the ground track,
residual by magnetic latitude, split-fit comparisons, residual in time), so it is one file.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.diagnose.attribution import Attribution
from orbitcal.diagnose.effects import EFFECT_NAMES, DiagnosisData, get_effect

__all__ = ["BASELINE_METHOD", "build_report", "report_html"]

FloatArray = npt.NDArray[np.float64]

#: Name of the baseline calibration in the report.
BASELINE_METHOD = "linear-12"


def _num(x: float) -> float | None:
    """JSON-safe float (NaN/inf -> None), rounded to 1e-4."""
    return None if not math.isfinite(x) else round(float(x), 4)


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
    effects = []
    for e in att.effects:
        eff = get_effect(e.name)
        effects.append(
            {
                "name": e.name,
                "significant": bool(e.significant),
                "holdout_rms_before_nt": _num(e.holdout_rms_before_nt),
                "holdout_rms_after_nt": _num(e.holdout_rms_after_nt),
                "shrink": _num(e.shrink),
                "params": _clean(e.params),
                "p_value": float(f"{e.p_value:.3g}"),
                "unique_rms_increase_nt": _num(e.unique_rms_increase_nt),
                "selection_step": e.step,
                "witness": eff.witness,
            }
        )
    t = data.t_utc_s
    from orbitcal.timescales import utc_s_to_iso

    start, end = utc_s_to_iso([float(t[0]), float(t[-1])])
    held = att.holdout
    report: dict[str, Any] = {
        "baseline": {
            "method": BASELINE_METHOD,
            "holdout_rms_nt": _num(att.baseline_rms_nt),
            "train_rms_nt": _num(att.baseline_train_rms_nt),
            "reference_field": data.reference_field,
            "calibration_prior": (
                data.calibration_prior.summary() if data.calibration_prior is not None else None
            ),
        },
        "verdict": att.verdict,
        "effects": effects,
        "where": _clean(where),
        "final": {
            "effects": list(att.selected),
            "holdout_rms_nt": _num(att.final_rms_nt),
            "shrink": _num(att.baseline_rms_nt / max(att.final_rms_nt, 1e-12)),
            "where": _clean(where_final) if where_final is not None else None,
        },
        "split_fits": [
            _clean(
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
            for s in att.split_fits
        ],
        "data": {
            "start": start,
            "end": end,
            "n": int(data.n),
            "n_train": int((~held).sum()),
            "n_holdout": int(held.sum()),
            "holdout": "later time blocks (last 30 % of the span) that no fit saw",
            "candidates_without_witness": sorted(set(EFFECT_NAMES) - {e.name for e in att.effects}),
            "crust_model": data.crust_model,
        },
    }
    if learned is not None:
        report["learned"] = _clean(learned)
    return report


# ---- HTML --------------------------------------------------------------------------------------


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _figures(
    report: dict[str, Any], data: DiagnosisData | None, att: Attribution | None
) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: list[tuple[str, str]] = []
    eff = report["effects"]
    if eff:
        fig, ax = plt.subplots(figsize=(7, 3))
        names = [e["name"] for e in eff]
        shr = [e["shrink"] or 0.0 for e in eff]
        colors = ["tab:red" if e["significant"] else "tab:gray" for e in eff]
        ax.barh(names[::-1], shr[::-1], color=colors[::-1])
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_xlabel("held-out shrink (before / after)")
        ax.set_title("Shrink per candidate effect (red: selected)")
        figs.append(("Shrink per effect", _png(fig)))
    bands = report["where"].get("magnetic_latitude", [])
    if bands:
        fig, ax = plt.subplots(figsize=(7, 3))
        labels = [f"{b['band_deg'][0]:g}-{b['band_deg'][1]:g}" for b in bands]
        x = np.arange(len(bands))
        ax.bar(x - 0.2, [b["rms_nt"] for b in bands], 0.4, label="vector")
        ax.bar(x + 0.2, [b["scalar_rms_nt"] for b in bands], 0.4, label="scalar (along B)")
        ax.set_xticks(x, labels)
        ax.set_xlabel("|magnetic latitude| band [deg]")
        ax.set_ylabel("residual RMS [nT]")
        ax.legend()
        figs.append(("Residual by magnetic latitude", _png(fig)))
    if data is not None and att is not None:
        r = att.baseline_residual_nt
        lat = np.degrees(np.arcsin(data.r_itrs_km[:, 2] / np.linalg.norm(data.r_itrs_km, axis=1)))
        lon = np.degrees(np.arctan2(data.r_itrs_km[:, 1], data.r_itrs_km[:, 0]))
        fig, ax = plt.subplots(figsize=(8, 4))
        sc = ax.scatter(lon, lat, c=np.linalg.norm(r, axis=1), s=4, cmap="viridis")
        fig.colorbar(sc, ax=ax, label="|residual| [nT]")
        ax.set_xlabel("longitude [deg]")
        ax.set_ylabel("latitude [deg]")
        ax.set_xlim(-180, 180)
        ax.set_ylim(-90, 90)
        ax.set_title("Baseline residual along the ground track")
        figs.append(("Residual map", _png(fig)))
        fig, ax = plt.subplots(figsize=(8, 3))
        th = (data.t_utc_s - data.t_utc_s[0]) / 3600.0
        ax.plot(th, np.linalg.norm(r, axis=1), lw=0.6, label="baseline")
        ax.plot(
            th, np.linalg.norm(att.final_residual_nt, axis=1), lw=0.6, label="with selected effects"
        )
        ax.axvspan(th[att.holdout][0], th[-1], color="0.9", label="held out")
        ax.set_xlabel("time [h]")
        ax.set_ylabel("|residual| [nT]")
        ax.legend(loc="upper left")
        figs.append(("Residual in time", _png(fig)))
    splits = report.get("split_fits", [])
    if splits:
        fig, axes = plt.subplots(1, len(splits), figsize=(3.2 * len(splits), 3), squeeze=False)
        for ax, s in zip(axes[0], splits, strict=True):
            off = np.array(s["offsets_nt"], dtype=float)
            off = off - off.mean(axis=0)
            for k, axis in enumerate("xyz"):
                ax.plot(range(len(off)), off[:, k], "o-", label=axis)
            ax.set_xticks(range(len(off)), s["labels"], rotation=30, fontsize=7)
            ax.set_title(f"{s['name']} (z={s['z']:.1f})", fontsize=9)
            ax.set_ylabel("offset - mean [nT]")
        axes[0][0].legend(fontsize=7)
        figs.append(("Split fits", _png(fig)))
    return figs


def report_html(
    report: dict[str, Any],
    *,
    data: DiagnosisData | None = None,
    attribution: Attribution | None = None,
    title: str = "orbitcal diagnosis",
) -> str:
    """A self-contained HTML page of a report (plots embedded as base64 PNG)."""
    rows = "".join(
        f"<tr><td>{html.escape(e['name'])}</td><td>{'yes' if e['significant'] else 'no'}</td>"
        f"<td>{e['holdout_rms_before_nt']}</td><td>{e['holdout_rms_after_nt']}</td>"
        f"<td>{e['shrink']}</td><td>{e['p_value']}</td></tr>"
        for e in report["effects"]
    )
    figs = "".join(
        f"<h2>{html.escape(name)}</h2>"
        f"<img alt='{html.escape(name)}' src='data:image/png;base64,{png}'/>"
        for name, png in _figures(report, data, attribution)
    )
    where = html.escape(json.dumps(report["where"], indent=1)[:20000])
    return (
        "<!doctype html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title>"
        "<style>body{font-family:sans-serif;max-width:960px;margin:auto}"
        "td,th{padding:2px 8px;border-bottom:1px solid #ddd}</style></head><body>"
        f"<h1>{html.escape(title)}</h1>"
        f"<p>Verdict: <b>{html.escape(str(report['verdict']))}</b>. Baseline "
        f"{html.escape(report['baseline']['method'])} held-out RMS "
        f"{report['baseline']['holdout_rms_nt']} nT; with the selected effects "
        f"{report['final']['holdout_rms_nt']} nT (shrink {report['final']['shrink']}).</p>"
        "<table><tr><th>effect</th><th>significant</th><th>before [nT]</th><th>after [nT]</th>"
        f"<th>shrink</th><th>p</th></tr>{rows}</table>{figs}"
        f"<h2>Where (JSON)</h2><pre>{where}</pre></body></html>"
    )
