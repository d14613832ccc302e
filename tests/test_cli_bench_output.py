"""``orbitcal bench diagnose`` when its output is not a terminal (issue 47): a plain line per
world instead of a bar that draws nothing for minutes, and shares with nothing to count said in
words (a draw without a null world printed ``false alarms on null nan%``)."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from orbitcal.cli.bench import summary_line

ROOT = Path(__file__).resolve().parents[1]


def test_a_summary_without_null_or_effect_worlds_says_so() -> None:
    nan = math.nan
    s = {
        "cases": 2,
        "top1": 0.5,
        "top1_strict": 0.5,
        "unobservable_cases": 0,
        "min_top1_per_effect": nan,
        "false_alarm_rate": nan,
        "shrink_vs_oracle_mean": nan,
        "shrink_vs_oracle_pooled": nan,
    }
    line = summary_line(s, 12.0)
    assert "nan" not in line.lower()
    assert "false alarms on null no null world" in line
    assert "min per effect no effect world" in line and "top-1 50.0%" in line
    s |= {"false_alarm_rate": 0.0, "min_top1_per_effect": 1.0, "shrink_vs_oracle_mean": 0.91}
    line = summary_line(s, 12.0)
    assert "false alarms on null 0.0%" in line and "shrink vs oracle 0.910" in line


@pytest.mark.slow
def test_bench_diagnose_prints_a_plain_line_per_world_into_a_pipe(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "orbitcal", "bench", "diagnose", "--cases", "2", "--seed", "0"]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=env, check=True)
    lines = out.stdout.splitlines()
    worlds = [x for x in lines if x.startswith("world ")]
    assert len(worlds) == 2, out.stdout
    for k, line in enumerate(worlds, start=1):
        assert re.fullmatch(
            rf"world {k}/2: \w+ -> \w+ \((right|wrong)\); top-1 so far [\d.]+%, \d+ s", line
        ), line
    assert "nan" not in out.stdout.lower() and "\x1b[" not in out.stdout + out.stderr
    (summary,) = [x for x in lines if x.startswith("cases 2:")]
    assert "false alarms on null " in summary
