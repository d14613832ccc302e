"""Our simulator's panels with each diagnosis engine on the same worlds, in one run (issue 43).

    python benchmarks/diagnose_engines.py --panel blind --cases 240 --seed S --engine both \
        --out RUN.json.gz
    python benchmarks/diagnose_engines.py --panel compound --cases 50 --seed S --engine both \
        --out RUN.json.gz

runs what ``orbitcal bench diagnose [--compound] --cases N --seed S`` runs
(``orbitcal.diagnose.bench.run_benchmark`` / ``run_compound_benchmark``), once per engine,
with the benchmark's options (``bench.BENCH_OPTIONS``) given
``engine=ENGINE``; the worlds are the seed's, the same for each engine. The run's JSON holds each
engine's summary and cases; ``benchmarks/independent/tables.py --engines`` puts the panels side by
side. Until ``DiagnosisOptions.model`` has its ``engine`` field only ``--engine rules`` runs (the
default engine) and the others stop with a message saying so.
"""

from __future__ import annotations

import argparse
import gzip
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks" / "independent"))
from engine_cli import engine_support, options_with_engine  # noqa: E402


def _engines(choice: str) -> tuple[list[str], str]:
    engines = ["rules", "model"] if choice == "both" else [choice]
    if engine_support():
        return engines, "option"
    if engines != ["rules"]:
        raise SystemExit(
            f"cannot run engine(s) {engines}: orbitcal.diagnose.options.DiagnosisOptions has no "
            "field 'engine' (issue 43's model-based core is not in this checkout); only "
            "--engine rules runs, as the default engine"
        )
    return engines, "default"


def run_panel(panel: str, cases: int, seed: int, engine: str, chosen_by: str) -> dict[str, Any]:
    """One engine's run of ``panel`` (``blind`` or ``compound``)."""
    from orbitcal.data import real_tles_text
    from orbitcal.diagnose import bench

    saved, saved_diagnosed = bench.BENCH_OPTIONS, bench._diagnosed
    if chosen_by == "option":
        bench.BENCH_OPTIONS = options_with_engine(saved, engine)
    if engine == "model":
        bench._diagnosed = _reported_verdict
    try:
        run = bench.run_compound_benchmark if panel == "compound" else bench.run_benchmark
        t0 = time.time()
        result = run(cases, seed=seed, tle_text=real_tles_text())
        result["wall_s"] = round(time.time() - t0, 1)
        return result
    finally:
        bench.BENCH_OPTIONS, bench._diagnosed = saved, saved_diagnosed


def _reported_verdict(data: Any) -> Any:
    """The world's attribution with the *report's* verdict and named effects.

    ``orbitcal.diagnose.bench`` scores the rules engine's ``Attribution``; the model engine's
    verdict exists only in the report (``orbitcal.diagnose.model.with_model_keys``), so under it
    the verdict, the selected effects (significant in the report, most probable first) and the
    verdict's probability are taken from there. The held-out RMS columns stay the attribution's
    final fit under both engines (the model core's own are the report's ``confirmation``).
    Without this the model column scored the rules engine's verdict (VALIDATION.md)."""
    import dataclasses

    from orbitcal.diagnose import bench
    from orbitcal.diagnose.api import diagnose_data

    diagnosis = diagnose_data(data, options=bench.BENCH_OPTIONS)
    report = diagnosis.report
    named = [str(e["name"]) for e in report["effects"] if e.get("significant")]
    return dataclasses.replace(
        diagnosis.attribution,
        verdict=str(report["verdict"]),
        selected=named,
        verdict_confidence=report.get("verdict_probability"),
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--panel", choices=("blind", "compound"), required=True)
    ap.add_argument("--cases", type=int, required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--engine", choices=("rules", "model", "both"), default="rules")
    ap.add_argument("--out", type=Path, required=True, help="RUN.json or RUN.json.gz")
    args = ap.parse_args(argv)
    engines, chosen_by = _engines(args.engine)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=REPO
    ).stdout.strip()
    t0 = time.time()
    doc = {
        "panel": args.panel,
        "commit": commit,
        "command": f"python benchmarks/diagnose_engines.py --panel {args.panel} "
        f"--cases {args.cases} --seed {args.seed} --engine {args.engine}",
        "engine_chosen_by": chosen_by,
        "engines": {e: run_panel(args.panel, args.cases, args.seed, e, chosen_by) for e in engines},
    }
    doc["wall_s"] = round(time.time() - t0, 1)
    doc["rows"] = []  # the per-world rows are in each engine's "cases"
    text = json.dumps(doc, indent=1, default=float)
    if args.out.suffix == ".gz":
        args.out.write_bytes(gzip.compress(text.encode(), mtime=0))
    else:
        args.out.write_text(text)
    for e in engines:
        print(e, json.dumps(doc["engines"][e]["summary"], default=float)[:2000])
    return 0


if __name__ == "__main__":
    sys.exit(main())
