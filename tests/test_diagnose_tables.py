"""benchmarks/results/diagnose.md's figures are the output of benchmarks/diagnose_tables.py on the
results it keeps beside it (diagnose_results_seed<S>.json): they cannot drift from a run."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _script():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location(
        "diagnose_tables", ROOT / "benchmarks" / "diagnose_tables.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_page_holds_the_scripts_output_on_the_kept_results() -> None:
    tables = _script()
    page = (RESULTS / "diagnose.md").read_text()
    start, end = page.index(tables.BEGIN), page.index(tables.END)
    shown = page[start + len(tables.BEGIN) : end].strip()
    kept = sorted(RESULTS.glob("diagnose_results_seed*.json"))
    assert kept, "no kept benchmark results"
    runs = [json.loads(p.read_text()) for p in kept]
    runs.sort(key=lambda r: r["settings"]["seed"])
    assert shown == tables.tables(runs).strip()


def test_the_readme_quotes_the_kept_seed_0_run() -> None:
    run = json.loads((RESULTS / "diagnose_results_seed0.json").read_text())
    s = run["summary"]
    row = next(
        line for line in (ROOT / "README.md").read_text().splitlines()
        if line.startswith("| blind diagnosis")
    )  # fmt: skip
    top1, strict = f"{100 * s['top1']:.1f} %", f"{100 * s['top1_strict']:.1f} %"
    assert top1 in row and strict in row, (row, top1, strict)
    assert re.search(rf"lowest effect ≥ {100 * s['min_top1_per_effect']:.0f} %", row), row
