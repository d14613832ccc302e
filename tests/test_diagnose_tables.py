"""benchmarks/diagnose_tables.py writes the figures of benchmarks/results/diagnose.md from a run's
results (``--update``): the page keeps the markers it writes between, and the tables it writes
are those of the results it keeps beside the page."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "benchmarks" / "results" / "diagnose.md"


def _script() -> Any:
    spec = importlib.util.spec_from_file_location(
        "diagnose_tables", ROOT / "benchmarks" / "diagnose_tables.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(seed: int, top1: float) -> dict[str, Any]:
    effect = {
        "cases": 2,
        "top1": 1.0,
        "top1_by_magnitude": {"1": 1.0},
        "median_shrink": 3.0,
        "median_oracle_shrink": 3.0,
        "mean_shrink_vs_oracle": 1.0,
        "mean_shrink_vs_perfect": 0.9,
    }
    return {
        "summary": {
            "top1": top1,
            "top1_strict": top1 - 0.01,
            "unobservable_cases": 1,
            "min_top1_per_effect": 0.85,
            "false_alarm_rate": 0.0,
            "null_cases": 1,
            "shrink_vs_oracle_mean": 1.0,
            "shrink_vs_oracle_pooled": 1.0,
            "shrink_vs_perfect_mean": 0.87,
            "per_effect": {"none": {"cases": 1, "top1": 1.0}, "temperature": effect},
        },
        "cases": [
            {
                "correct": False,
                "effect": "temperature",
                "magnitude": 1.0,
                "attitude": "nadir",
                "norad_id": 39452,
                "verdict": "none",
                "injected_rms_nt": 3.0,
                "baseline_holdout_rms_nt": 4.0,
                "oracle_holdout_rms_nt": 3.5,
            }
        ],
        "settings": {"seed": seed, "n_cases": 3},
        "machine": {"platform": "test", "python": "3.11", "wall_seconds": 12.0},
    }


def test_update_writes_the_tables_between_the_markers_and_keeps_the_results(
    tmp_path: Path,
) -> None:
    tables = _script()
    page = PAGE.read_text()
    assert page.count(tables.BEGIN) == page.count(tables.END) == 1  # --update can run on it
    copy = tmp_path / "diagnose.md"
    copy.write_text(page)
    runs = []
    for seed, top1 in ((0, 0.988), (1, 0.97)):
        d = tmp_path / f"seed{seed}"
        d.mkdir()
        (d / "diagnose_results.json").write_text(json.dumps(_run(seed, top1)))
        runs.append(str(d))
    assert tables.main(["--update", str(copy), *runs]) == 0
    text = copy.read_text()
    block = text[text.index(tables.BEGIN) + len(tables.BEGIN) : text.index(tables.END)]
    assert "| top-1 accuracy, all cases | **98.8%** (strict 97.8%; 1 worlds without a gap)" in block
    assert "| 1 | 97.0% (96.0% strict) |" in block and "| temperature | 1 | nadir |" in block
    # everything outside the markers is kept
    for doc in (text, page):
        assert doc.index(tables.BEGIN) == page.index(tables.BEGIN)
    assert text[text.index(tables.END) :] == page[page.index(tables.END) :]
    kept = tables.load_kept(tmp_path / "diagnose_results_seed0.json.gz")
    assert tables.tables([kept, _run(1, 0.97)]).strip() == block.strip()


def test_the_page_holds_the_scripts_output_on_the_kept_results() -> None:
    tables = _script()
    page = PAGE.read_text()
    shown = page[page.index(tables.BEGIN) + len(tables.BEGIN) : page.index(tables.END)]
    kept = sorted(PAGE.parent.glob("diagnose_results_seed*.json.gz"))
    runs = sorted((tables.load_kept(p) for p in kept), key=lambda r: r["settings"]["seed"])
    assert runs, "no kept benchmark results beside benchmarks/results/diagnose.md"
    assert shown.strip() == tables.tables(runs).strip()


def test_the_readme_quotes_the_kept_seed_0_run() -> None:
    s = _script().load_kept(PAGE.parent / "diagnose_results_seed0.json.gz")["summary"]
    row = next(
        line for line in (ROOT / "README.md").read_text().splitlines()
        if line.startswith("| blind diagnosis")
    )  # fmt: skip
    assert f"{100 * s['top1']:.1f} % top-1 ({100 * s['top1_strict']:.1f} % strict)" in row, row
    assert f"lowest effect ≥ {int(100 * s['min_top1_per_effect'])} %" in row, row
    assert f"{100 * s['false_alarm_rate']:.0f} false alarms" in row or (
        s["false_alarm_rate"] == 0 and "0 false alarms" in row
    ), row
