"""End to end on a world dated November 2026, past the shipped RC index (ends 2026-05-08).

The TLE is synthetic: the last real Swarm A element set of tests/authorities/swarm_iss_real_tles.tle
(epoch 2023-11-19) with only its epoch moved to 2026-11-11 12:00 UTC (checksum recomputed), so no
stale-epoch override is needed. simulate → truth → calibrate → diagnose through the CLI, with an
empty data directory: the shipped tables are in use, and the results (truth, calibration
document, diagnosis report JSON and HTML) must say that the RC index ends before the data, that
UT1 − UTC is a prediction, and which external-field variant ran instead.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from orbitcal import auxdata
from orbitcal.cli import main as cli_main
from orbitcal.orbit import tle_checksum

AUTHORITIES = Path(__file__).resolve().parent / "authorities"


def swarm_a_tle_nov2026() -> str:
    lines = (AUTHORITIES / "swarm_iss_real_tles.tle").read_text().splitlines()
    i = max(k for k, line in enumerate(lines) if line.startswith("1 39452U"))
    line1, line2 = lines[i], lines[i + 1]
    assert line1[18:32] == "23323.56602589"
    moved = line1[:18] + "26315.50000000" + line1[32:68]
    moved += str(tle_checksum(moved))
    return f"SWARM A (epoch moved to 2026-11-11)\n{moved}\n{line2}\n"


@pytest.fixture
def empty_data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    d = tmp_path / "data"
    monkeypatch.setenv("ORBITCAL_DATA_DIR", str(d))
    auxdata.reload()
    yield d  # type: ignore[misc]
    monkeypatch.delenv("ORBITCAL_DATA_DIR")
    auxdata.reload()


def test_november_2026_world_end_to_end(
    tmp_path: Path, empty_data_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tle = tmp_path / "swarm_a_nov2026.tle"
    tle.write_text(swarm_a_tle_nov2026())
    world = tmp_path / "world"
    args = ["simulate", "--tle", str(tle), "--start", "2026-11-12T00:00:00Z",
            "--duration-s", "21600", "--cadence-s", "10", "--effect", "external_field",
            "--seed", "3", "--out", str(world)]  # fmt: skip
    assert cli_main(args) == 0
    telemetry = str(world / "telemetry.csv")
    sc_tle = str(world / "spacecraft.tle")
    truth_csv = tmp_path / "truth.csv"
    capsys.readouterr()
    assert cli_main(["truth", telemetry, "--tle", sc_tle, "--out", str(truth_csv)]) == 0
    assert "UT1 - UTC is predicted" in capsys.readouterr().err
    cal = tmp_path / "cal.json"
    assert cli_main(["calibrate", telemetry, "--tle", sc_tle, "--method", "linear",
                     "--out", str(cal), "--quiet"]) == 0  # fmt: skip
    doc = json.loads(cal.read_text())
    prov = doc["provenance"]
    assert prov["tables"]["leap_seconds"]["status"] == "valid"
    assert prov["tables"]["leap_seconds"]["valid_until"] == "2027-06-28T00:00:00Z"
    assert prov["tables"]["eop"]["status"] == "predicted"
    assert prov["reference_field"]["models"][0]["generation"] == "14"

    report_path = tmp_path / "report.json"
    html_path = tmp_path / "report.html"
    with pytest.warns(UserWarning, match="RC index not used"):
        code = cli_main(["diagnose", telemetry, "--tle", sc_tle, "--out", str(report_path),
                         "--html", str(html_path)])  # fmt: skip
    assert code == 0
    report = json.loads(report_path.read_text())
    rc = report["provenance"]["tables"]["rc_index"]
    assert rc["status"] == "past_end"
    assert rc["coverage_end"] == "2026-05-08T09:29:59Z"
    assert rc["used"] is False
    # Without the RC index the external field is estimated from the data alone: the dipole-axis
    # field with a linear trend, a recovery-phase decay or a storm's main phase and recovery
    # (chosen by training BIC), never a variant driven by the RC index or the RC model.
    data_only = ("dipole_axis", "recovery_", "storm@")
    assert rc["external_field_variant"].startswith(data_only)
    assert rc["external_field_variant"].endswith(
        "(estimated from the data; no RC index for these dates)"
    )
    assert any("RC index" in w for w in report["provenance"]["warnings"])
    assert report["provenance"]["tables"]["eop"]["status"] == "predicted"
    ext = next(e for e in report["effects"] if e["name"] == "external_field")
    assert ext["params"]["variant"].startswith(data_only)
    assert rc["external_field_variant"].startswith(ext["params"]["variant"] + " ")
    assert report["verdict"] == "external_field"
    html = html_path.read_text()
    assert "Tables used" in html and "past_end" in html and "RC index" in html
