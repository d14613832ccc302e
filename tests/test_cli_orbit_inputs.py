"""``--tle`` on the command line (issue 11 item 7): many sets and ``--norad``, OMM files, stale
elements refused unless ``--allow-stale-elements``, one-line summaries and warnings, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from sgp4.exporter import export_omm
from shared_worlds import REAL_TLES_FILE

from orbitcal.cli import main
from orbitcal.orbit import read_tle_sets


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli-orbit") / "world"
    argv = ["simulate", "--tle", str(REAL_TLES_FILE), "--norad", "39452"]
    argv += ["--start", "2022-08-02T00:00:00Z", "--duration-s", "600", "--cadence-s", "10"]
    assert main([*argv, "--attitude", "tumbling", "--seed", "1", "--out", str(out)]) == 0
    return out


def _truth(world: Path, tmp_path: Path, *extra: str) -> int:
    tel = str(world / "telemetry.csv")
    return main(["truth", tel, *extra, "--out", str(tmp_path / "truth.csv")])


def test_many_sets_need_norad_and_use_the_nearest(
    world: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _truth(world, tmp_path, "--tle", str(REAL_TLES_FILE)) == 2
    assert "--norad" in capsys.readouterr().err
    assert _truth(world, tmp_path, "--tle", str(REAL_TLES_FILE), "--norad", "39452") == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("truth: 60 samples 2022-08-02T00:00:00Z")


def test_an_omm_file_is_accepted_wherever_tle_is(world: Path, tmp_path: Path) -> None:
    sets = [o for o in read_tle_sets(REAL_TLES_FILE.read_text()) if o.norad_id == 39452]
    omm = tmp_path / "swarm_a.json"
    omm.write_text(json.dumps([export_omm(o.satrec, o.name) for o in sets]))
    assert _truth(world, tmp_path, "--tle", str(omm)) == 0


def test_stale_elements_exit_2_unless_allowed(
    world: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    latest = max(
        (o for o in read_tle_sets(REAL_TLES_FILE.read_text()) if o.norad_id == 39452),
        key=lambda o: o.epoch_utc_s,
    )  # 2023-11: over a year after the data
    old = tmp_path / "old.tle"
    old.write_text(latest.to_tle_text())
    assert _truth(world, tmp_path, "--tle", str(old)) == 2
    err = capsys.readouterr().err
    assert "days from the data, more than 14 days" in err and "--allow-stale-elements" in err
    # In a real process (pytest records warnings itself): exit 0 and the warning on one line.
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "orbitcal",
            "truth",
            str(world / "telemetry.csv"),
            "--tle",
            str(old),
            "--allow-stale-elements",
            "--out",
            str(tmp_path / "t.csv"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    warning = [ln for ln in proc.stderr.splitlines() if ln]
    assert len(warning) == 1 and warning[0].startswith("orbitcal truth: warning: NORAD 39452")


def test_unphysical_elements_exit_2_naming_the_field(
    world: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.json"
    sets = [o for o in read_tle_sets(REAL_TLES_FILE.read_text()) if o.norad_id == 39452]
    record = {k: str(v) for k, v in export_omm(sets[0].satrec, "SWARM A").items()}
    bad.write_text(json.dumps({**record, "ELEMENT_SET_NO": str(10**30)}))
    assert _truth(world, tmp_path, "--tle", str(bad)) == 2
    assert "ELEMENT_SET_NO" in capsys.readouterr().err
