"""Markdown tables of a blind-diagnosis benchmark run (``orbitcal bench diagnose --out DIR``).

``python benchmarks/diagnose_tables.py DIR [DIR ...]`` prints the headline, per-effect and misses
tables of the first run and one summary line per further run (other seeds).

``python benchmarks/diagnose_tables.py --update benchmarks/results/diagnose.md DIR [DIR ...]``
writes them into that file between its ``<!-- diagnose_tables: begin -->`` and
``<!-- diagnose_tables: end -->`` markers and keeps each run's ``diagnose_results.json`` beside it
as ``diagnose_results_seed<S>.json.gz`` (compressed; and the first run's
``diagnose_confusion.{json,png}``): the figures of the page are the script's output on committed
results, and ``tests/test_diagnose_tables.py`` checks that they still are.
"""

from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path
from typing import Any


def _pct(x: float) -> str:
    return f"{100.0 * x:.1f}%"


def load_kept(path: Path) -> dict[str, Any]:
    """A run kept beside the page (``diagnose_results_seed*.json.gz``)."""
    return json.loads(gzip.decompress(path.read_bytes()))  # type: ignore[no-any-return]


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


BEGIN = "<!-- diagnose_tables: begin -->"
END = "<!-- diagnose_tables: end -->"


def machine_line(run: dict[str, Any]) -> str:
    m, st = run.get("machine", {}), run.get("settings", {})
    return (
        f"Run: `orbitcal bench diagnose --cases {st.get('n_cases', '?')} --seed "
        f"{st.get('seed', '?')}`; machine {m.get('platform', '?')}, Python {m.get('python', '?')}, "
        f"wall time {m.get('wall_seconds', float('nan')):.0f} s."
    )


def tables(runs: list[dict[str, Any]]) -> str:
    """The generated part of benchmarks/results/diagnose.md."""
    parts = [
        machine_line(runs[0]),
        "\n## Headline\n",
        headline(runs[0]),
        "\n## Per effect\n",
        per_effect(runs[0]),
        "\n## Misses\n",
        misses(runs[0]),
        "\n## Every seed run with this code\n",
        "| seed | top-1 | lowest per effect | null false alarms | shrink/oracle | wall [s] |",
        "|---|---|---|---|---|---|",
        *[summary_line(run) for run in runs],
    ]
    return "\n".join(parts)


def update(page: Path, directories: list[str]) -> None:
    """Rewrite the marked part of ``page`` and keep the runs' results beside it."""
    import shutil

    runs = [_load(d) for d in directories]
    text = page.read_text()
    start, end = text.index(BEGIN), text.index(END)
    page.write_text(text[: start + len(BEGIN)] + "\n" + tables(runs) + "\n" + text[end:])
    for run in runs:
        seed = run["settings"]["seed"]
        # compressed: the raw run stays beside the page only because the page's test reads it
        target = page.parent / f"diagnose_results_seed{seed}.json.gz"
        target.write_bytes(gzip.compress((json.dumps(run, indent=0) + "\n").encode(), mtime=0))
    first = Path(directories[0])
    for name in ("diagnose_confusion.json", "diagnose_confusion.png"):
        if (first / name).exists():
            shutil.copy(first / name, page.parent / name)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--update"] and len(argv) >= 3:
        update(Path(argv[1]), argv[2:])
        return 0
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    print(tables([_load(d) for d in argv]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
