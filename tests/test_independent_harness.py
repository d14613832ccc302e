"""The independent harness (``benchmarks/independent/run_worlds.py``, ``tables.py``,
``engine_cli.py``) scores each engine's reports on the same worlds: recall, spurious worlds,
verdict, null false alarms by noise kind and the reliability of reported probabilities; and it
refuses an engine the checkout cannot run with a message naming the missing option."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1] / "benchmarks" / "independent"
sys.path.insert(0, str(HERE))

import common  # noqa: E402
import engine_cli  # noqa: E402
import run_worlds  # noqa: E402
import tables  # noqa: E402

from orbitcal.diagnose.options import DiagnosisOptions  # noqa: E402


def _report(verdict: str, effects: list[tuple[str, bool, float | None]]) -> dict:
    return {
        "verdict": verdict,
        "baseline": {"holdout_rms_nt": 5.0},
        "effects": [
            {"name": n, "significant": s, **({"probability": p} if p is not None else {})}
            for n, s, p in effects
        ],
    }


def _row(world: int, injected: list[str], noise: str, by_engine: dict[str, dict]) -> dict:
    return {
        "world": world,
        "injected": injected,
        "noise": noise,
        "samples": 1000,
        "make_s": 1.0,
        "truth": {},
        "engines": {
            e: {**run_worlds.score(rep, injected, {}), "wall_s": 2.0}
            for e, rep in by_engine.items()
        },
    }


def _rows() -> list[dict]:
    return [
        _row(
            0,
            ["temperature", "sun_driven"],
            "pink",
            {
                "rules": _report("temperature", [("temperature", True, None)]),
                "model": _report(
                    "temperature",
                    [
                        ("temperature", True, 0.95),
                        ("sun_driven", True, 0.85),
                        ("crustal_field", False, 0.1),
                    ],
                ),
            },
        ),
        _row(
            1,
            ["magnetorquer"],
            "per_axis",
            {
                "rules": _report(
                    "magnetorquer", [("magnetorquer", True, None), ("orbit_error", True, None)]
                ),
                "model": _report(
                    "magnetorquer", [("magnetorquer", True, 0.9), ("orbit_error", False, 0.2)]
                ),
            },
        ),
        _row(
            2,
            [],
            "ar1",
            {
                "rules": _report("time_offset", [("time_offset", True, None)]),
                "model": _report("none", [("time_offset", False, 0.05)]),
            },
        ),
        _row(3, [], "white", {"rules": _report("none", []), "model": _report("none", [])}),
    ]


def test_each_engine_is_scored_on_the_same_worlds() -> None:
    rows = _rows()
    rules, model = run_worlds.summarise(rows, "rules"), run_worlds.summarise(rows, "model")
    assert rules["compound_worlds"] == model["compound_worlds"] == 2
    assert rules["recall"] == pytest.approx(2 / 3) and model["recall"] == 1.0
    assert rules["recall_by_effect"]["sun_driven"] == {"found": 0, "injected": 1}
    assert rules["worlds_with_spurious"] == 0.5 and model["worlds_with_spurious"] == 0.0
    assert rules["verdict_among_injected"] == model["verdict_among_injected"] == 1.0
    assert rules["null_false_alarm_rate"] == 0.5 and model["null_false_alarm_rate"] == 0.0
    assert rules["null_by_noise_kind"]["ar1"]["false_alarm_rate"] == 1.0
    assert model["null_by_noise_kind"]["ar1"]["false_alarm_rate"] == 0.0
    # probabilities only where the reports give them
    assert rules["reliability"] == {"pairs": 0}
    assert model["reliability"]["pairs"] == 6


def test_reliability_bins_and_expected_calibration_error() -> None:
    perfect = [(0.2, False)] * 4 + [(0.2, True)] + [(0.8, True)] * 4 + [(0.8, False)]
    rel = run_worlds.reliability(perfect)
    assert rel["ece"] == pytest.approx(0.0, abs=1e-12)
    assert [b["n"] for b in rel["bins"]] == [5, 5]
    overconfident = [(0.95, True), (0.95, False)]
    assert run_worlds.reliability(overconfident)["ece"] == pytest.approx(0.45)
    assert run_worlds.reliability([(1.0, True)])["bins"][0]["bin"] == [0.9, 1.0]


def test_the_side_by_side_page_has_a_column_per_engine() -> None:
    run = {"commit": "abc", "command": "run_worlds.py --engine both", "wall_s": 9.0}
    run |= {"engines": {"rules": {}, "model": {}}, "rows": _rows()}
    page = tables.engines_page([run], "tuning seeds")
    assert "| | rules | model |" in page
    assert (
        "| recall (injected effects named significant) | 2 of 3 = 66.7 % | 3 of 3 = 100.0 % |"
        in page
    )
    assert "| ar1 | 1 of 1 = 100.0 % | 0 of 1 = 0.0 % |" in page
    assert "rules: the reports give no `probability`" in page and "model: 6 (probability" in page


def test_the_plan_draws_one_to_three_effects_under_coloured_noise_and_every_null_kind() -> None:
    plan = run_worlds.plan(12345, 40, 2)
    effect_worlds, null_worlds = plan[:40], plan[40:]
    assert {len(e) for e, _, _ in effect_worlds} == {1, 2, 3}
    assert {n for _, n, _ in effect_worlds} == set(run_worlds.EFFECT_NOISE)
    kinds = [n for _, n, _ in null_worlds]
    assert sorted(set(kinds)) == sorted(run_worlds.NOISE_KINDS) and len(kinds) == 16
    assert plan == run_worlds.plan(12345, 40, 2)  # a seed names its worlds


def test_an_engine_the_checkout_cannot_run_is_refused_with_the_reason() -> None:
    has_engine = "engine" in {f.name for f in dataclasses.fields(DiagnosisOptions().model)}
    assert engine_cli.engine_support() == has_engine
    assert common.check_engines(["rules"]) == ("option" if has_engine else "default")
    if has_engine:
        assert common.check_engines(["rules", "model"]) == "option"
    else:
        with pytest.raises(SystemExit, match="DiagnosisOptions has no field 'engine'"):
            common.check_engines(["rules", "model"])
        assert engine_cli.main(["model", "diagnose", "x.csv", "--out", "y.json"]) == 2


def test_the_readme_quotes_the_validation_page() -> None:
    """The README's row of the two engines is the validation page's figures, never typed."""
    root = HERE.parents[1]
    page = (root / "benchmarks" / "results" / "diagnose_engines_validation.md").read_text()
    row = next(
        line for line in (root / "README.md").read_text().splitlines()
        if line.startswith("| the two diagnosis engines side by side")
    )  # fmt: skip
    figures = tables.readme_figures(page)
    assert figures.startswith("independent worlds: recall ") and " / " in figures
    assert figures in row, (figures, row)
