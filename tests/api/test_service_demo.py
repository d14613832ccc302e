"""The README's first command: ``orbitcal demo`` runs the main job end to end (short span)."""

from __future__ import annotations

import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest


@pytest.mark.slow  # 30-100 s (a 0.7-day demo); > 300 s at load 24 on 2 cores
def test_orbitcal_demo_recovers_after_the_parameter_change(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "orbitcal", "demo", "--days", "0.7", "--dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    out = proc.stdout
    assert proc.returncode == 0, (out[-3000:], proc.stderr[-3000:])
    assert "sensor parameters change at" in out
    assert re.search(r"streamed 6048 samples in 17 uploads", out)
    assert "360 duplicates, 0 new" in out
    m = re.search(r"in service: version (\d+) .* leaves (\d+\.\d+) nT rms", out)
    assert m is not None and int(m.group(1)) >= 2 and float(m.group(2)) < 10.0
    assert "superseded" in out
    # the version history says why it can differ from run to run
    assert "the number of versions can differ from run to run" in out
    # Without --keep-serving the service stops: no links to it, no URL of it, and it says so.
    assert "/dashboard#key=" not in out and "service has stopped" in out
    assert "http://" not in out
    # APScheduler's "skipped: maximum number of running instances" is no warning, and nothing
    # the service logs is plain text
    assert "maximum number of running instances" not in proc.stderr
    for line in proc.stderr.splitlines():
        assert line.startswith("{") or "warning:" in line, line
    assert (tmp_path / "orbitcal.sqlite").exists()


#: The keep-serving demo must be gone this long after Ctrl-C: its shutdown is bounded by the
#: connections' deadline (ORBITCAL_SHUTDOWN_TIMEOUT_S, 10 s) and the jobs' (the same), so this is
#: a deadline for a hang, far above what the shutdown takes on a loaded machine.
HANG_DEADLINE_S = 120


def _hammer(link: str, key: str, stop: threading.Event) -> None:
    """GET ``link`` in a loop until ``stop`` (or the server is gone)."""
    import urllib.error
    import urllib.request

    request = urllib.request.Request(link, headers={"X-API-Key": key})
    while not stop.is_set():
        try:
            with urllib.request.urlopen(request, timeout=10) as r:
                r.read()
        except (OSError, urllib.error.URLError):
            if stop.wait(0.05):
                return


@pytest.mark.slow  # 30-100 s
def test_orbitcal_demo_keep_serving_serves_until_ctrl_c(tmp_path: Path) -> None:
    """With --keep-serving the printed links answer, and Ctrl-C stops it with a plain message."""
    import signal
    import time
    import urllib.request

    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orbitcal",
            "demo",
            "--days",
            "0.7",
            "--dir",
            str(tmp_path),
            "--keep-serving",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        lines: list[str] = []
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if line.strip() == "Ctrl-C stops the service.":
                break
        out = "".join(lines)
        assert "serving until Ctrl-C" in out, (out, proc.poll())
        m = re.search(r"dashboard\s+(http://127\.0\.0\.1:\d+)/dashboard#key=(\S+)", out)
        assert m is not None, out
        url, key = m.group(1), m.group(2)
        # what a browser opens as printed answers without a header (the key rides in the
        # fragment); what needs the key is printed as a curl line that sends it
        for link in (f"{url}/dashboard", f"{url}/docs", f"{url}/healthz"):
            with urllib.request.urlopen(link, timeout=30) as r:
                assert r.status == 200, link
        calibrations = f"curl -H 'X-API-Key: {key}' {url}/v1/spacecraft/swarm-a/calibrations"
        assert f"calibrations  {calibrations}" in out
        assert f"metrics       curl -H 'X-API-Key: {key}' {url}/metrics" in out
        assert "telemetry" not in out.split("Where to look")[1]  # was the calibrations' label
        request = urllib.request.Request(
            f"{url}/v1/spacecraft/swarm-a/calibrations", headers={"X-API-Key": key}
        )
        with urllib.request.urlopen(request, timeout=30) as r:
            assert r.status == 200
        # Ctrl-C while clients hammer the service and a retraining was just asked for: the
        # shutdown is bounded whatever runs (the connections get the shutdown deadline, a
        # retraining still running is left behind).
        retrain = urllib.request.Request(
            f"{url}/v1/spacecraft/swarm-a/calibrations", headers={"X-API-Key": key}, method="POST"
        )
        with urllib.request.urlopen(retrain, timeout=30) as r:
            assert r.status == 202
        stop = threading.Event()
        hammers = [
            threading.Thread(target=_hammer, args=(link, key, stop), daemon=True)
            for link in (f"{url}/healthz", f"{url}/v1/spacecraft/swarm-a/calibration") * 3
        ]
        for t in hammers:
            t.start()
        proc.send_signal(signal.SIGINT)
        # a deadline for a hang, not a measure of speed (the shutdown itself takes seconds)
        rest, err = proc.communicate(timeout=HANG_DEADLINE_S)
        stop.set()
    finally:
        if proc.poll() is None:
            proc.kill()
    # 0, or 1 when the calibration missed 10 nT (timing-dependent retraining on a loaded machine:
    # the first test holds the demo to 10 nT); never a traceback or a signal's exit status.
    assert proc.returncode in (0, 1), (out[-2000:], rest[-2000:], err[-2000:])
    assert "Traceback" not in err, err[-3000:]
    assert "the service has stopped" in rest
