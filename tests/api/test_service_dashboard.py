"""The dashboard page end to end in headless Debian chromium (marked ``browser``)."""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from service_helpers import ADMIN_KEY, live_server, sqlite_settings, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

pytestmark = pytest.mark.browser

IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}


def _chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        if IN_CI:
            pytest.fail("Debian chromium is not installed (.ci/run installs it)")
        pytest.skip("chromium is not installed")
    return path


def test_dashboard_shows_spacecraft_versions_residuals_and_diagnosis(tmp_path: Path) -> None:
    chromium = _chromium()
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        assert (
            c.post("/v1/spacecraft", json={"id": "swarm-a", "tle": SWARM_A_TLE}).status_code == 201
        )
        df, _ = world(T0_UTC_S, 3000, positions=False)
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        r = c.post(
            "/v1/spacecraft/swarm-a/telemetry",
            content=buf.getvalue(),
            headers={"content-type": "application/vnd.apache.parquet"},
        )
        assert r.json()["accepted"] == 3000
        job = wait_job(c, c.post("/v1/spacecraft/swarm-a/calibrations").json()["job_id"])
        assert job["status"] == "succeeded"
        assert c.get("/v1/spacecraft/swarm-a/diagnosis?cached=true").status_code == 404
        # a report as orbitcal.diagnose would leave it (computing one takes minutes): the page
        # must show the latest one
        report = {
            "baseline": {"method": "linear", "holdout_rms_nt": 12.5},
            "verdict": "temperature",
            "effects": [
                {
                    "name": "temperature",
                    "significant": True,
                    "holdout_rms_before_nt": 12.5,
                    "holdout_rms_after_nt": 2.1,
                    "shrink": 5.95,
                    "params": {},
                }
            ],
            "where": {"axis_rms_nt": [7.0, 6.0, 8.0]},
        }
        server.app.state.diagnosis_cache[("swarm-a", False)] = (3000, report)
        assert c.get("/v1/spacecraft/swarm-a/diagnosis?cached=true").json() == report
        assert c.get("/v1/spacecraft/swarm-a/diagnosis").json() == report  # current: no recompute
        profile = tmp_path / "chromium-profile"
        proc = subprocess.run(
            [
                chromium,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--no-first-run",
                "--disable-dev-shm-usage",
                f"--user-data-dir={profile}",
                "--virtual-time-budget=20000",
                "--dump-dom",
                f"{server.url}/dashboard#key={ADMIN_KEY}",
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
    dom = proc.stdout
    assert 'data-ready="swarm-a"' in dom, (proc.returncode, proc.stderr[-2000:], dom[-3000:])
    assert re.search(r'<tr class="sc sel" data-id="swarm-a"><td>swarm-a</td>', dom)
    # calibration in service and its history
    assert '"version": 1' in dom
    assert re.search(r'<td>1</td><td class="in_service">in_service</td>', dom)
    # residual-vs-time plot: a polyline with one point per sample shown
    m = re.search(r'<polyline points="([^"]+)"[^>]*id="residual-line"', dom)
    assert m is not None and len(m.group(1).split()) >= 500
    assert re.search(r"RMS \d+\.\d+ nT per component", dom)
    # latest diagnosis: a section-5 verdict, or the service's stated reason why not
    diag = re.search(r'<pre id="diagnosis">(.*?)</pre>', dom, re.S)
    assert diag is not None and diag.group(1).startswith("verdict: temperature")
    assert '"holdout_rms_after_nt": 2.1' in diag.group(1)
    assert 'id="run-diagnosis"' in dom
    assert ADMIN_KEY not in dom.replace(f"#key={ADMIN_KEY}", "")
