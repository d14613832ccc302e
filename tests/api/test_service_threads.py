"""``service.threads.DaemonPool``: a shutdown is bounded whatever still runs, and the process exits.

The retraining and diagnosis pools ran on ``ThreadPoolExecutor``, whose threads the interpreter
joins at exit: a job still running kept ``orbitcal demo --keep-serving`` alive after Ctrl-C."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from service.threads import DaemonPool

REPO = Path(__file__).resolve().parents[2]

#: A process whose pool runs a call that never ends, then leaves ``main``. The bound below is a
#: deadline for a hang, not a speed: the exit takes well under a second.
NEVER_ENDING = """
import sys, threading
from service.threads import DaemonPool
started = threading.Event()
pool = DaemonPool(1, "t")
pool.submit(lambda: (started.set(), threading.Event().wait()))
started.wait()
print(pool.shutdown(timeout_s=0.1), flush=True)
"""


def test_a_process_exits_although_its_pool_still_runs_a_call() -> None:
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    done = subprocess.run(
        [sys.executable, "-c", NEVER_ENDING], env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"  # the call was left behind, and the process went


def test_shutdown_cancels_what_has_not_started_and_results_come_back() -> None:
    pool = DaemonPool(1, "t")
    release = threading.Event()
    first = pool.submit(release.wait)
    queued = pool.submit(lambda: "never")
    assert pool.submit(lambda x: x * 2, 21) is not None
    ok = pool.submit(lambda: 1)  # queued behind the first
    release.set()
    assert first.result(timeout=60) is True
    assert queued.result(timeout=60) == "never" and ok.result(timeout=60) == 1
    failing = pool.submit(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        failing.result(timeout=60)
    blocker, started = threading.Event(), threading.Event()
    running = pool.submit(lambda: (started.set(), blocker.wait())[1])
    pending = pool.submit(lambda: "cancelled")
    assert started.wait(timeout=60)
    assert pool.shutdown(timeout_s=0.1) is False  # the running call is left behind
    assert pending.cancelled()
    with pytest.raises(RuntimeError, match="shut down"):
        pool.submit(lambda: 0)
    blocker.set()
    assert running.result(timeout=60) is True


def test_without_cancelling_queued_work_runs_within_the_deadline() -> None:
    """The retraining runner's shutdown: what was submitted runs if the deadline allows."""
    pool = DaemonPool(1, "t")
    release = threading.Event()
    first = pool.submit(release.wait)
    queued = pool.submit(lambda: "ran")
    release.set()
    assert pool.shutdown(timeout_s=60, cancel_pending=False) is True
    assert first.result(timeout=0) is True and queued.result(timeout=0) == "ran"
