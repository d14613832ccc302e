"""One RMS per question (issue 47): the same table and method give the same held-out RMS through
``orbitcal calibrate``, the library and the service, each at its DEFAULT hold-out share
(``orbitcal.calibrate.holdout.HOLDOUT_FRACTION``), and the service's health series opens with
that same number; ``calibrate`` prints the noise estimate beside it."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from orbitcal.calibrate.holdout import HOLDOUT_FRACTION
from orbitcal.reproduce.onorbit import orbit_world
from orbitcal.telemetry import write_telemetry

NOISE_NT = 5.0


def test_calibrate_library_and_service_give_one_held_out_rms(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sys.path.insert(0, str(Path(__file__).parent / "api"))
    from service_helpers import live_server, sqlite_settings, wait_job

    import orbitcal
    from orbitcal.cli import main
    from orbitcal.orbit import Orbit

    world = orbit_world(
        attitude="tumbling", n_samples=2000, noise_std_nt=NOISE_NT, rng=np.random.default_rng(7)
    )
    csv, tle, out = tmp_path / "w.csv", tmp_path / "w.tle", tmp_path / "cal.json"
    write_telemetry(csv, world.telemetry)
    tle.write_text(world.tle)
    # the CLI, defaults but the method
    argv = ["calibrate", str(csv), "--tle", str(tle), "--method", "linear", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    cli = json.loads(out.read_text())["metrics"]
    assert cli["holdout_fraction"] == HOLDOUT_FRACTION == 0.25
    assert cli["n_holdout"] == 500
    # the noise estimate printed beside the held-out RMS, and stored in the document
    assert cli["holdout_noise_nt"] == pytest.approx(NOISE_NT, rel=0.1)
    ratio = cli["holdout_rms_nt"] / cli["holdout_noise_nt"]
    assert (
        f"linear: {cli['holdout_rms_nt']:.3f} nT held out (RMS over the last 25 % of 2000 "
        f"samples: 500), {ratio:.1f}\u00d7 the noise of {cli['holdout_noise_nt']:.1f} nT"
    ) in printed, printed
    # the library, defaults but the method
    run = orbitcal.calibrate_table(
        orbitcal.read_table(csv), orbit=Orbit.from_tle(world.tle), method="linear"
    )
    lib = run.document["metrics"]
    assert lib["holdout_rms_nt"] == pytest.approx(cli["holdout_rms_nt"], rel=1e-9)
    # the service, default settings (method linear, hold-out share HOLDOUT_FRACTION)
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "w", "tle": world.tle}).status_code == 201
        r = c.post("/v1/spacecraft/w/telemetry", content=csv.read_bytes(),
                   headers={"content-type": "text/csv"})  # fmt: skip
        assert r.status_code == 200, r.text
        job = wait_job(c, c.post("/v1/spacecraft/w/calibrations").json()["job_id"])
        assert job["status"] == "succeeded", job
        version = c.get("/v1/spacecraft/w/calibrations").json()[0]
        series = c.get("/v1/spacecraft/w/health/series").json()
        health = c.get("/v1/spacecraft/w/health").json()
    assert version["document"]["metrics"]["holdout_fraction"] == HOLDOUT_FRACTION
    for value in (
        job["result"]["holdout_rms_nt"],
        version["holdout_rms_nt"],
        version["document"]["metrics"]["holdout_rms_nt"],
        series[0]["rms_nt"],  # the health series opens on the same rows
        health["recent_rms_nt"],
    ):
        assert value == pytest.approx(cli["holdout_rms_nt"], rel=1e-9)
    assert series[0]["kind"] == "holdout"
    assert health["noise_nt"] == pytest.approx(cli["holdout_noise_nt"], rel=1e-9)
