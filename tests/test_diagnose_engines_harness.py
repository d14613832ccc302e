"""benchmarks/diagnose_engines.py scores each engine's own verdict (issue 43, VALIDATION.md).

``orbitcal.diagnose.bench`` scores the rules engine's ``Attribution``; under the model engine
the harness must score the report's verdict and named effects, which the model core writes.
The run of seeds 20100/20200 scored the rules engine's verdict in both columns."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

import pytest
from test_diagnose_worlds import make_world

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.usefixtures("single_thread_blas")


def _harness() -> Any:
    sys.path.insert(0, str(REPO / "benchmarks" / "independent"))
    spec = importlib.util.spec_from_file_location(
        "diagnose_engines", REPO / "benchmarks" / "diagnose_engines.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_model_column_scores_the_reports_verdict(monkeypatch: pytest.MonkeyPatch) -> None:
    from orbitcal.diagnose import bench
    from orbitcal.diagnose.api import diagnose_data

    harness = _harness()
    world = make_world("magnetorquer", attitude="tumbling", seed=2)
    seen: list[tuple[str, list[str]]] = []
    scorer: list[bool] = []
    rules_diagnosed = bench._diagnosed

    def run(cases: int, *, seed: int, tle_text: str) -> dict[str, Any]:
        scorer.append(bench._diagnosed is rules_diagnosed)
        att = bench._diagnosed(world.data)
        seen.append((att.verdict, list(att.selected)))
        return {"cases": []}

    monkeypatch.setattr(bench, "run_benchmark", run)
    harness.run_panel("blind", 1, 0, "model", "option")
    assert bench._diagnosed is rules_diagnosed  # restored
    options = harness.options_with_engine(bench.BENCH_OPTIONS, "model")
    report = diagnose_data(world.data, options=options).report
    named = [e["name"] for e in report["effects"] if e.get("significant")]
    assert seen == [(report["verdict"], named)]
    assert report["model"]["engine"] == "model"

    harness.run_panel("blind", 1, 0, "rules", "option")  # the rules column: its attribution
    rules = diagnose_data(world.data, options=bench.BENCH_OPTIONS).attribution
    assert seen[-1] == (rules.verdict, list(rules.selected))
    assert scorer == [False, True]
