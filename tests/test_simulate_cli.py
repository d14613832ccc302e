"""``orbitcal simulate`` end to end (small worlds)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from orbitcal.cli import main
from orbitcal.telemetry import read_telemetry


def _args(authorities: Path, out: Path, *extra: str) -> list[str]:
    return [
        "simulate",
        "--tle",
        str(authorities / "swarm_iss_real_tles.tle"),
        "--norad",
        "39452",
        "--start",
        "2023-07-05T00:00:00Z",
        "--duration-s",
        "1200",
        "--cadence-s",
        "10",
        "--out",
        str(out),
        *extra,
    ]


@pytest.mark.parametrize("fmt", ["csv", "parquet", "ndjson", "json"])
def test_simulate_writes_a_readable_world(
    tmp_path: Path, authorities: Path, fmt: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / fmt
    rc = main(
        _args(
            authorities,
            out,
            "--attitude",
            "tumbling",
            "--effect",
            "temperature:bias_nt_per_c=3/0/-3",
            "--effect",
            "time_offset:offset_s=1",
            "--seed",
            "4",
            "--format",
            fmt,
        )
    )
    assert rc == 0
    assert "120 samples of NORAD 39452" in capsys.readouterr().out
    res = read_telemetry(out / f"telemetry.{fmt}")
    assert res.rejected == [] and len(res.telemetry) == 120
    tel = res.telemetry
    assert tel.q_wxyz is not None and tel.temperature_c is not None and tel.mtq_am2 is not None
    truth = json.loads((out / "truth.json").read_text())
    assert [e["name"] for e in truth["effects"]] == ["temperature", "time_offset"]
    assert truth["effects"][0]["params"]["bias_nt_per_c"] == [3.0, 0.0, -3.0]
    assert truth["attitude"]["profile"] == "tumbling" and truth["seed"] == 4


def test_same_seed_same_world(tmp_path: Path, authorities: Path) -> None:
    for name in ("a", "b"):
        assert main(_args(authorities, tmp_path / name, "--seed", "9")) == 0
    a = read_telemetry(tmp_path / "a" / "telemetry.csv").telemetry
    b = read_telemetry(tmp_path / "b" / "telemetry.csv").telemetry
    np.testing.assert_array_equal(a.b_raw_nt, b.b_raw_nt)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--effect", "wobble"], "unknown effect 'wobble'"),
        (["--effect", "time_offset:speed=2"], "no parameter 'speed'"),
        (["--duration-s", "-5"], "positive"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    tmp_path: Path,
    authorities: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    assert main(_args(authorities, tmp_path / "x", *extra)) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_file_with_many_spacecraft_needs_norad(
    tmp_path: Path, authorities: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = _args(authorities, tmp_path / "x")
    i = args.index("--norad")
    del args[i : i + 2]
    assert main(args) == 2
    assert "--norad" in capsys.readouterr().err


def test_sensor_change_half_way(tmp_path: Path, authorities: Path) -> None:
    out = tmp_path / "change"
    assert main(_args(authorities, out, "--sensor", "wang2020", "--sensor-change-at-s", "600")) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["sensor"]["b0_nt"] == [-633.2, 1281.7, -455.5]
    np.testing.assert_allclose(truth["sensor_after"]["b0_nt"], [-652.7, 1266.4, -444.49])
    assert truth["sensor_change"] == "2023-07-05T00:10:00.000000Z"
