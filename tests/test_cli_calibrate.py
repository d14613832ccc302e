"""``orbitcal calibrate`` and ``orbitcal apply`` as in CONTRACT section 2."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from orbitcal.cli import main
from orbitcal.pipeline import apply_document
from orbitcal.reproduce.onorbit import orbit_world, write_tle
from orbitcal.telemetry import read_telemetry, write_telemetry


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("cli")
    w = orbit_world(
        n_samples=800, rng=np.random.default_rng(51), temperature=True, magnetorquer=True
    )
    tel = d / "tel.csv"
    write_telemetry(tel, w.telemetry)
    return tel, write_tle(d / "swarm.tle", w.tle)


@pytest.mark.parametrize("method", ["lmbp-hk", "linear", "twostep"])
def test_calibrate_then_apply(files: tuple[Path, Path], tmp_path: Path, method: str) -> None:
    tel, tle = files
    cal = tmp_path / "cal.json"
    out = tmp_path / "out.csv"
    assert (
        main(
            [
                "calibrate",
                str(tel),
                "--tle",
                str(tle),
                "--method",
                method,
                "--out",
                str(cal),
                "--quiet",
            ]
        )
        == 0
    )
    doc = json.loads(cal.read_text())
    assert doc["method"] == method and doc["spacecraft"] == "SWARM A"
    assert doc["metrics"]["holdout_rms_nt"] > 0
    assert main(["apply", str(cal), str(tel), "--out", str(out)]) == 0
    with out.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time", "b_x", "b_y", "b_z"]
    assert len(rows) == 801
    expected = apply_document(doc, read_telemetry(tel).telemetry)
    got = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)


def test_progress_display_runs(files: tuple[Path, Path], tmp_path: Path) -> None:
    tel, tle = files
    assert main(["calibrate", str(tel), "--tle", str(tle), "--out", str(tmp_path / "c.json")]) == 0


def test_bad_input_exits_non_zero_with_one_line(
    files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tel, tle = files
    out = str(tmp_path / "c.json")
    assert main(["calibrate", str(tel), "--out", out]) == 2  # no positions and no TLE
    assert "--tle" in capsys.readouterr().err
    assert main(["calibrate", str(tel), "--tle", str(tle), "--method", "nope", "--out", out]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown method" in err and "\n" not in err
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["apply", str(bad), str(tel), "--out", out]) == 2
    assert "not a calibration document" in capsys.readouterr().err
