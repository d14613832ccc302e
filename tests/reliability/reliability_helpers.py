"""Helpers of the reliability suite: real server processes, cheap telemetry, SQLite inspection.

Everything talks to 127.0.0.1 only. Telemetry here needs no physics (ingest does not compute the
reference field), so batches are generated directly as CSV text with unique, known times: a
sample is identified by its time, and a batch by its first time.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import uvicorn
from shared_worlds import SWARM_A_2022_TLE

from service.app import create_app
from service.settings import Settings

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
ADMIN_KEY = "rel-admin-" + uuid.uuid4().hex
#: 2022-08-01T00:00:00Z: inside IGRF-14's definitive span and the Swarm A TLE's epoch.
T0_UTC_S = 1_659_312_000.0
#: Swarm A (NORAD 39452), CelesTrak, epoch 2022-08-01 (tests/shared_worlds.py).
SWARM_A_TLE = SWARM_A_2022_TLE
CSV = {"content-type": "text/csv"}


def _root_conftest() -> Any:
    spec = importlib.util.spec_from_file_location(
        "_reliability_root_conftest", HERE.parent / "conftest.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: ``require_service(name, port)`` of tests/conftest.py: skips locally, fails in CI.
require_service = _root_conftest().require_service


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def csv_batch(t0_s: float, n: int, *, dt_s: float = 1.0, seed: int = 0) -> bytes:
    """``n`` samples at ``t0_s + dt_s * k`` [POSIX s] with raw fields of ~3e4 nT, as CSV."""
    rng = np.random.default_rng(seed)
    b = rng.normal(0.0, 2e4, (n, 3))
    t = t0_s + dt_s * np.arange(n)
    lines = ["time,b_x,b_y,b_z"]
    lines += [f"{ti:.6f},{x:.3f},{y:.3f},{z:.3f}" for ti, (x, y, z) in zip(t, b, strict=True)]
    return ("\n".join(lines) + "\n").encode()


def stored_times_us(db: Path, spacecraft: str) -> np.ndarray:
    """Every stored sample time [µs] of one spacecraft, read straight from the SQLite file."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30)
    try:
        rows = con.execute(
            "SELECT s.t_utc_us FROM samples s JOIN spacecraft c ON c.pk = s.spacecraft_pk "
            "WHERE c.id = ? ORDER BY s.t_utc_us",
            (spacecraft,),
        ).fetchall()
    finally:
        con.close()
    return np.array([r[0] for r in rows], dtype=np.int64)


def sqlite_query(db: Path, sql: str, params: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30)
    try:
        return list(con.execute(sql, params).fetchall())
    finally:
        con.close()


def wait_healthy(url: str, *, timeout_s: float = 60.0, pid: int | None = None) -> float:
    """Poll ``/healthz`` until it answers 200; return the seconds waited."""
    t0 = time.monotonic()
    while True:
        try:
            if httpx.get(url + "/healthz", timeout=1.0).status_code == 200:
                return time.monotonic() - t0
        except httpx.TransportError:
            pass
        if pid is not None and not pid_alive(pid):
            raise RuntimeError(f"server process {pid} exited before answering {url}/healthz")
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError(f"{url} did not become healthy in {timeout_s:g} s")
        time.sleep(0.05)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - not ours
        return True
    try:  # a zombie is dead for our purposes
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False


def kill9(pid: int, *, timeout_s: float = 10.0) -> None:
    """``kill -9`` one process we started and wait until it is gone."""
    os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + timeout_s
    while pid_alive(pid):
        if time.monotonic() > deadline:
            raise RuntimeError(f"process {pid} survived SIGKILL for {timeout_s:g} s")
        time.sleep(0.01)


class ForkServer:
    """Client of ``forkserver.py``: forks real server/worker processes from a warm parent."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE / "forkserver.py")],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=open(log_dir / "forkserver.log", "ab"),  # noqa: SIM115 - owned by the process
            text=True,
            env=env,
            cwd=str(log_dir),
        )
        self.children: list[int] = []
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if line != "ready":
            raise RuntimeError(f"fork server did not start (said {line!r}); see forkserver.log")

    def spawn(self, spec: dict[str, Any]) -> int:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        spec = {"log": str(self.log_dir / "children.log"), **spec}
        self.proc.stdin.write(json.dumps(spec) + "\n")
        self.proc.stdin.flush()
        pid = int(self.proc.stdout.readline())
        self.children.append(pid)
        return pid

    def close(self) -> None:
        for pid in self.children:
            if pid_alive(pid):
                os.kill(pid, signal.SIGKILL)
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)

    def log_text(self) -> str:
        path = self.log_dir / "children.log"
        return path.read_text(errors="replace") if path.exists() else ""


@contextmanager
def fork_server(log_dir: Path) -> Iterator[ForkServer]:
    fs = ForkServer(log_dir)
    try:
        yield fs
    finally:
        fs.close()


def sqlite_settings(db: Path, **overrides: Any) -> dict[str, Any]:
    """Settings (as a JSON-able dict) of a service on the SQLite file ``db``."""
    values: dict[str, Any] = {
        "database_url": f"sqlite:///{db}",
        "admin_key": ADMIN_KEY,
        "scheduler": False,
        "log_level": "WARNING",
    }
    values.update(overrides)
    return values


class LiveServer:
    """uvicorn in a thread of the test process (for in-process fault injection and log capture)."""

    def __init__(self, app: Any, *, log_level: str = "warning") -> None:
        self.app = app
        config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level=log_level, lifespan="on")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.url = ""

    def start(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + 60
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        port = self.server.servers[0].sockets[0].getsockname()[1]
        self.url = f"http://127.0.0.1:{port}"
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=30)

    def client(self, key: str | None = ADMIN_KEY, **kwargs: Any) -> httpx.Client:
        headers = {"X-API-Key": key} if key else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=60, **kwargs)


@contextmanager
def live_server(
    settings: Settings, *, log_level: str = "warning", **kwargs: Any
) -> Iterator[LiveServer]:
    server = LiveServer(create_app(settings, **kwargs), log_level=log_level).start()
    try:
        yield server
    finally:
        server.stop()


def physical_csv(t0_s: float, n: int, *, dt_s: float = 10.0, seed: int = 0) -> bytes:
    """``n`` calibratable samples: IGRF-14 along Swarm A's orbit seen by a tumbling body, through a
    known sensor (gains ~1, offsets ~100 nT, 2 nT noise), as CSV with quaternions and positions."""
    from scipy.spatial.transform import Rotation

    from orbitcal.orbit import Orbit
    from orbitcal.truth import truth_body_nt

    rng = np.random.default_rng(seed)
    t = t0_s + dt_s * np.arange(n)
    dt = t - T0_UTC_S
    eph = Orbit.from_tle(SWARM_A_TLE).propagate(t)
    r = np.asarray(eph.r_itrs_km)
    rotvec = np.stack([dt * 2e-3, dt * 1.3e-3 + 0.4, 0.7 + dt * 0.7e-3], axis=-1)
    xyzw = Rotation.from_rotvec(rotvec).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    b_body = truth_body_nt(t, r, q, attitude_frame="GCRS", field="IGRF-14")
    M = np.array([[1.02, 0.01, -0.005], [0.0, 0.98, 0.02], [0.0, 0.0, 1.01]])
    b_raw = b_body @ np.linalg.inv(M).T + np.array([120.0, -80.0, 45.0])
    b_raw += rng.normal(0.0, 2.0, b_raw.shape)
    lines = ["time,b_x,b_y,b_z,q_w,q_x,q_y,q_z,r_x,r_y,r_z"]
    for i in range(n):
        vals = [*b_raw[i], *q[i], *r[i]]
        lines.append(f"{t[i]:.6f}," + ",".join(f"{v:.17g}" for v in vals))
    return ("\n".join(lines) + "\n").encode()
