"""Markdown tables of a blind-diagnosis benchmark run (``orbitcal bench diagnose --out DIR``).

``python benchmarks/diagnose_tables.py DIR [DIR ...]`` prints the headline, per-effect and misses
tables of the first run and one summary line per further run (other seeds), for
``benchmarks/results/diagnose.md``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def _pct(x: float) -> str:
    return f"{100.0 * x:.1f}%"


def _load(directory: str) -> dict[str, Any]:
    return json.loads((Path(directory) / "diagnose_results.json").read_text())  # type: ignore[no-any-return]


def headline(run: dict[str, Any]) -> str:
    s = run["summary"]
    return "\n".join(
        [
            "| metric | result | target |",
            "|---|---|---|",
            f"| top-1 accuracy, all cases | **{_pct(s['top1'])}** "
            f"(strict {_pct(s['top1_strict'])}; {s['unobservable_cases']} worlds without a gap) "
            "| >= 95 % |",
            f"| lowest per-effect top-1 | **{_pct(s['min_top1_per_effect'])}** | >= 85 % |",
            f"| false alarms on null worlds | **{_pct(s['false_alarm_rate'])}** "
            f"({s['null_cases']} null worlds) | <= 5 % |",
            "| held-out shrink / oracle's shrink (mean over effect worlds) | "
            f"**{s['shrink_vs_oracle_mean']:.3f}** (pooled {s['shrink_vs_oracle_pooled']:.3f}) "
            "| >= 0.90 |",
            "| held-out shrink / perfect oracle's shrink (mean) | "
            f"{s['shrink_vs_perfect_mean']:.3f} | (information) |",
        ]
    )


def per_effect(run: dict[str, Any]) -> str:
    rows = [
        "| injected | cases | top-1 | top-1 by magnitude | median shrink | median oracle shrink "
        "| shrink/oracle (mean) | shrink/perfect (mean) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, e in run["summary"]["per_effect"].items():
        if name == "none":
            rows.append(f"| none | {e['cases']} | {_pct(e['top1'])} | - | - | - | - | - |")
            continue
        mags = ", ".join(f"{k}: {100 * v:.0f}%" for k, v in e["top1_by_magnitude"].items())
        rows.append(
            f"| {name} | {e['cases']} | {_pct(e['top1'])} | {mags} | {e['median_shrink']:.2f} "
            f"| {e['median_oracle_shrink']:.2f} | {e['mean_shrink_vs_oracle']:.3f} "
            f"| {e['mean_shrink_vs_perfect']:.3f} |"
        )
    return "\n".join(rows)


def misses(run: dict[str, Any]) -> str:
    rows = [
        "| injected | magnitude | attitude | NORAD | verdict | injected RMS [nT] "
        "| baseline held-out RMS [nT] | oracle held-out RMS [nT] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in run["cases"]:
        if c["correct"]:
            continue
        rows.append(
            f"| {c['effect']} | {c['magnitude']:g} | {c['attitude']} | {c['norad_id']} "
            f"| {c['verdict']} | {c['injected_rms_nt']:.1f} "
            f"| {c['baseline_holdout_rms_nt']:.2f} | {c['oracle_holdout_rms_nt']:.2f} |"
        )
    return "\n".join(rows)


def summary_line(run: dict[str, Any]) -> str:
    s = run["summary"]
    return (
        f"| {run['settings']['seed']} | {_pct(s['top1'])} ({_pct(s['top1_strict'])} strict) "
        f"| {_pct(s['min_top1_per_effect'])} "
        f"| {_pct(s['false_alarm_rate'])} | {s['shrink_vs_oracle_mean']:.3f} "
        f"| {run['machine']['wall_seconds']:.0f} |"
    )


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    runs = [_load(d) for d in argv]
    print("## Headline\n")
    print(headline(runs[0]))
    print("\n## Per effect\n")
    print(per_effect(runs[0]))
    print("\n## Misses\n")
    print(misses(runs[0]))
    print("\n## Every seed\n")
    print("| seed | top-1 | lowest per effect | null false alarms | shrink/oracle | wall [s] |")
    print("|---|---|---|---|---|---|")
    for run in runs:
        print(summary_line(run))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
