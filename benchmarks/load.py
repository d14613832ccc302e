"""Bounded load test of the service on loopback: mixed ingest and reads from many clients.

``orbitcal serve`` runs in its own process on an SQLite file (the embedded default). Before the
load, a few spacecraft are registered, given calibratable telemetry and retrained once, so every
read has something to answer. Then ``--clients`` concurrent closed-loop clients (asyncio + httpx,
one connection each) run for ``--duration`` seconds; each request is an ingest of a 100-sample
CSV batch with fresh times (share ``--ingest-share``) or one of four reads: the calibration in
service, the version history, the spacecraft, the job list entry of the first retraining.
The server's RSS (psutil) is sampled every 0.5 s.

Reported: throughput (requests/s, ingested samples/s), latency p50/p99 per kind, errors (any
answer other than the expected 200, or no answer), RSS over time and its growth between the
first and the last third of the run (after a warm-up).

Usage: ``python benchmarks/load.py [--duration 300] [--clients 50] [--out FILE.md]`` (default
``benchmarks/results/load.md``).
The test suite runs the same code for ~12 s (``tests/reliability/test_load.py``).

Reads under load (issue 15): ``python benchmarks/load.py --reads-only --duration 60 --clients 50
--compare-with REV --out benchmarks/results/load_reads.md`` runs only ``GET .../calibration``
with a lean HTTP/1.1 keep-alive client (raw asyncio streams: ~20 µs of client CPU per request
instead of httpx's ~400 µs, so that on 2 shared cores the figure is the server's) against the
server of this checkout and, side by side in the same run, against the server of git revision
``REV`` (checked out into a temporary worktree), alternating ``--rounds`` times.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import multiprocessing
import os
import platform
import queue
import secrets
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import psutil

REPO = Path(__file__).resolve().parents[1]
T0_UTC_S = 1_659_312_000.0  # 2022-08-01T00:00:00Z
SWARM_A_TLE = (
    "1 39452U 13067B   22213.51971877  .00001645  00000+0  50768-4 0  9990\n"
    "2 39452  87.3611 208.4349 0002354 100.1496 260.0021 15.32769581488835"
)
INGEST_ROWS = 100
KINDS = ("ingest", "calibration", "versions", "spacecraft", "job")


@dataclass
class LoadResult:
    duration_s: float
    clients: int
    counts: dict[str, int] = field(default_factory=dict)
    latencies_s: dict[str, list[float]] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    rss_mb: list[tuple[float, float]] = field(default_factory=list)  # (t [s], RSS [MB])
    samples_ingested: int = 0
    server_cpu_s: float = 0.0
    client_cpu_s: float = 0.0
    load_average: float = 0.0  # 1-minute load average at the end of the run

    @property
    def requests(self) -> int:
        return sum(self.counts.values())

    def percentile_ms(self, kind: str, q: float) -> float:
        lat = self.latencies_s.get(kind) or [float("nan")]
        return float(np.percentile(lat, q) * 1e3)

    def all_latencies_ms(self, q: float) -> float:
        lat = [x for v in self.latencies_s.values() for x in v] or [float("nan")]
        return float(np.percentile(lat, q) * 1e3)

    def rss_growth_mb(self, warmup_s: float) -> tuple[float, float, float]:
        """Median RSS [MB] of the first and last third after ``warmup_s``, and their difference."""
        after = [r for t, r in self.rss_mb if t >= warmup_s]
        if len(after) < 6:
            raise ValueError(f"only {len(after)} RSS samples after the warm-up")
        third = len(after) // 3
        first, last = float(np.median(after[:third])), float(np.median(after[-third:]))
        return first, last, last - first


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(
    db: Path,
    port: int,
    admin_key: str,
    log: Path,
    *,
    repo: Path = REPO,
    workers: int = 1,
    extra_env: dict[str, str] | None = None,
) -> subprocess.Popen[bytes]:
    env = {
        **os.environ,
        **(extra_env or {}),
        "ORBITCAL_ADMIN_KEY": admin_key,
        "ORBITCAL_LOG_LEVEL": "WARNING",
        "ORBITCAL_RATE_LIMIT_PER_S": "0",  # measure the service, not the limiter
        "PYTHONPATH": str(repo),
    }
    argv = [sys.executable, "-m", "orbitcal", "serve", "--port", str(port)]
    argv += ["--database", f"sqlite:///{db}", "--no-scheduler"]
    if workers > 1:
        argv += ["--workers", str(workers)]
    return subprocess.Popen(
        argv,
        env=env,
        cwd=str(repo),
        stdout=subprocess.DEVNULL,
        stderr=log.open("ab"),
    )


def wait_healthy(url: str, proc: subprocess.Popen[bytes], timeout_s: float = 120.0) -> None:
    t0 = time.monotonic()
    while True:
        try:
            if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                return
        except httpx.TransportError:
            pass
        if proc.poll() is not None:
            raise RuntimeError(f"server exited with {proc.returncode} before answering")
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError(f"server not healthy after {timeout_s:g} s")
        time.sleep(0.1)


def physical_csv(t0_s: float, n: int, *, dt_s: float = 10.0, seed: int = 0) -> bytes:
    """Calibratable samples (IGRF-14 along Swarm A's orbit, tumbling body, known sensor)."""
    from scipy.spatial.transform import Rotation

    from orbitcal.orbit import Orbit
    from orbitcal.truth import truth_body_nt

    rng = np.random.default_rng(seed)
    t = t0_s + dt_s * np.arange(n)
    dt = t - T0_UTC_S
    r = np.asarray(Orbit.from_tle(SWARM_A_TLE).propagate(t).r_itrs_km)
    rotvec = np.stack([dt * 2e-3, dt * 1.3e-3 + 0.4, 0.7 + dt * 0.7e-3], axis=-1)
    xyzw = Rotation.from_rotvec(rotvec).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    b = truth_body_nt(t, r, q, attitude_frame="GCRS", field="IGRF-14")
    b = b @ np.linalg.inv(np.diag([1.02, 0.98, 1.01])).T + [120.0, -80.0, 45.0]
    b += rng.normal(0.0, 2.0, b.shape)
    lines = ["time,b_x,b_y,b_z,q_w,q_x,q_y,q_z,r_x,r_y,r_z"]
    lines += [
        f"{t[i]:.6f}," + ",".join(f"{v:.17g}" for v in (*b[i], *q[i], *r[i])) for i in range(n)
    ]
    return ("\n".join(lines) + "\n").encode()


def prepare(url: str, admin_key: str, n_spacecraft: int) -> tuple[list[str], list[str], str]:
    """Register and calibrate spacecraft; return their ids, one job id each, and a read key."""
    ids = [f"load-{i}" for i in range(n_spacecraft)]
    jobs = []
    with httpx.Client(base_url=url, headers={"X-API-Key": admin_key}, timeout=120) as http:
        body = physical_csv(T0_UTC_S, 600)
        for sc in ids:
            assert http.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE}).is_success
            r = http.post(
                f"/v1/spacecraft/{sc}/telemetry", content=body, headers={"content-type": "text/csv"}
            )
            assert r.json()["accepted"] == 600, r.text
            jobs.append(http.post(f"/v1/spacecraft/{sc}/calibrations").json()["job_id"])
        for job_id in jobs:
            deadline = time.monotonic() + 300
            while (status := http.get(f"/v1/jobs/{job_id}").json()["status"]) not in (
                "succeeded",
                "failed",
            ):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"job {job_id} still {status}")
                time.sleep(0.2)
            if status != "succeeded":
                raise RuntimeError(f"preparation job {job_id} {status}")
        read_key = http.post("/v1/keys", json={"name": "load-reader", "scopes": ["read:*"]})
        return ids, jobs, read_key.json()["key"]


def _batch(client: int, k: int) -> bytes:
    # client c, batch k: times from 2022-09 on, 1 s apart, never overlapping another batch
    t0 = T0_UTC_S + 30 * 86400 + client * 10_000_000 + k * INGEST_ROWS
    rows = [
        f"{t0 + i:.1f},{2e4 + i:.1f},{-1e4 + k:.1f},{3e4 - client:.1f}" for i in range(INGEST_ROWS)
    ]
    return ("time,b_x,b_y,b_z\n" + "\n".join(rows) + "\n").encode()


async def _client(
    c: int,
    url: str,
    ids: list[str],
    jobs: list[str],
    admin_key: str,
    read_key: str,
    ingest_share: float,
    stop_at: float,
    result: LoadResult,
) -> None:
    rng = np.random.default_rng(c)
    k = 0
    limits = httpx.Limits(max_connections=1, max_keepalive_connections=1)
    async with httpx.AsyncClient(base_url=url, timeout=60, limits=limits) as http:
        while time.monotonic() < stop_at:
            i = int(rng.integers(len(ids)))
            sc = ids[i]
            if rng.random() < ingest_share:
                kind = "ingest"
                request = http.post(
                    f"/v1/spacecraft/{sc}/telemetry",
                    content=_batch(c, k),
                    headers={"X-API-Key": admin_key, "content-type": "text/csv"},
                )
                k += 1
            else:
                kind = KINDS[1 + int(rng.integers(4))]
                path = {
                    "calibration": f"/v1/spacecraft/{sc}/calibration",
                    "versions": f"/v1/spacecraft/{sc}/calibrations",
                    "spacecraft": f"/v1/spacecraft/{sc}",
                    "job": f"/v1/jobs/{jobs[i]}",
                }[kind]
                request = http.get(path, headers={"X-API-Key": read_key})
            t0 = time.perf_counter()
            try:
                r = await request
            except httpx.TransportError as exc:
                result.errors.append(f"{kind}: {type(exc).__name__}")
                continue
            dt = time.perf_counter() - t0
            if r.status_code != 200:
                result.errors.append(f"{kind}: {r.status_code} {r.text[:120]}")
                continue
            if kind == "ingest":
                result.samples_ingested += r.json()["accepted"]
            result.counts[kind] = result.counts.get(kind, 0) + 1
            result.latencies_s.setdefault(kind, []).append(dt)


def run_load(
    url: str,
    *,
    pid: int,
    ids: list[str],
    jobs: list[str],
    admin_key: str,
    read_key: str,
    clients: int = 50,
    duration_s: float = 12.0,
    ingest_share: float = 0.2,
) -> LoadResult:
    """Run the closed-loop load for ``duration_s`` and sample the server's RSS meanwhile."""
    result = LoadResult(duration_s=duration_s, clients=clients)
    proc = psutil.Process(pid)
    done = threading.Event()
    t_start = time.monotonic()

    def sample_rss() -> None:
        while not done.is_set():
            rss = proc.memory_info().rss + sum(
                ch.memory_info().rss for ch in proc.children(recursive=True)
            )
            result.rss_mb.append((time.monotonic() - t_start, rss / 2**20))
            done.wait(0.5)

    sampler = threading.Thread(target=sample_rss, daemon=True)
    sampler.start()

    async def main() -> None:
        stop_at = time.monotonic() + duration_s
        await asyncio.gather(
            *(
                _client(c, url, ids, jobs, admin_key, read_key, ingest_share, stop_at, result)
                for c in range(clients)
            )
        )

    try:
        asyncio.run(main())
    finally:
        done.set()
        sampler.join(timeout=5)
    result.duration_s = time.monotonic() - t_start
    return result


async def _raw_reader(
    c: int, port: int, paths: list[str], key: str, stop_at: float, result: LoadResult
) -> None:
    """One closed-loop client of ``GET`` requests on one keep-alive connection (raw HTTP/1.1)."""
    rng = np.random.default_rng(c)
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    requests = [
        f"GET {p} HTTP/1.1\r\nHost: 127.0.0.1\r\nX-API-Key: {key}\r\n\r\n".encode() for p in paths
    ]
    lat = result.latencies_s.setdefault("calibration", [])
    try:
        while time.monotonic() < stop_at:
            request = requests[int(rng.integers(len(requests)))]
            t0 = time.perf_counter()
            writer.write(request)
            status = int((await reader.readline()).split(b" ", 2)[1])
            length = 0
            while (line := await reader.readline()) not in (b"\r\n", b""):
                name, _, value = line.partition(b":")
                if name.strip().lower() == b"content-length":
                    length = int(value)
            body = await reader.readexactly(length)
            dt = time.perf_counter() - t0
            if status != 200 or not body.startswith(b"{"):
                result.errors.append(f"calibration: {status} {body[:120]!r}")
                continue
            result.counts["calibration"] = result.counts.get("calibration", 0) + 1
            lat.append(dt)
    except (OSError, asyncio.IncompleteReadError, ValueError, IndexError) as exc:
        result.errors.append(f"calibration: {type(exc).__name__}")
    finally:
        writer.close()


def run_reads(
    port: int, *, pid: int, ids: list[str], read_key: str, clients: int, duration_s: float
) -> LoadResult:
    """``clients`` closed-loop raw clients of ``GET .../calibration`` for ``duration_s``."""
    result = LoadResult(duration_s=duration_s, clients=clients)
    paths = [f"/v1/spacecraft/{sc}/calibration" for sc in ids]
    procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
    me = psutil.Process()

    def cpu_s(ps: list[psutil.Process]) -> float:
        return sum(t.user + t.system for t in (p.cpu_times() for p in ps))

    async def main() -> None:
        stop_at = time.monotonic() + duration_s
        await asyncio.gather(
            *(_raw_reader(c, port, paths, read_key, stop_at, result) for c in range(clients))
        )

    server0, client0 = cpu_s(procs), cpu_s([me])
    t0 = time.monotonic()
    try:
        import uvloop

        uvloop.run(main())
    except ImportError:  # pragma: no cover - uvloop is a dependency on Linux
        asyncio.run(main())
    result.duration_s = time.monotonic() - t0
    result.server_cpu_s = cpu_s(procs) - server0
    result.client_cpu_s = cpu_s([me]) - client0
    result.load_average = os.getloadavg()[0]
    return result


#: The attacks run beside the readers (``--attacks``): six clients each, in a process of their own.
ATTACKS = ("slow bodies", "header flood")
ATTACKERS = 6
FLOOD_BYTES = 32 * 2**20


def _flood_one(port: int, stop_at: float, answers: list[int]) -> None:
    """Requests with a 32 MiB header value, one after another, until ``stop_at``."""
    piece = b"a" * 65536
    while time.monotonic() < stop_at:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=60) as s:
                s.sendall(b"GET /v1/spacecraft HTTP/1.1\r\nHost: x\r\nX-Pad: ")
                sent = 0
                while sent < FLOOD_BYTES and not select.select([s], [], [], 0)[0]:
                    s.sendall(piece)
                    sent += len(piece)
                s.sendall(b"\r\n\r\n")
                head = s.recv(64)
                answers.append(int(head[9:12]) if head.startswith(b"HTTP/1.1 ") else -1)
        except OSError:
            answers.append(-1)


def _trickle_one(port: int, path: str, key: str, stop_at: float, answers: list[int]) -> None:
    """An upload that sends one byte every 0.5 s (under the idle limit) until ``stop_at``."""
    while time.monotonic() < stop_at:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=60) as s:
                s.sendall(
                    f"POST {path} HTTP/1.1\r\nHost: x\r\nX-API-Key: {key}\r\n"
                    f"Content-Type: text/csv\r\nContent-Length: {2**20}\r\n\r\n"
                    "time,b_x\r\n".encode()
                )
                while time.monotonic() < stop_at and not select.select([s], [], [], 0.5)[0]:
                    s.sendall(b"1")
                head = s.recv(64) if time.monotonic() < stop_at else b""
                if head:
                    answers.append(int(head[9:12]) if head.startswith(b"HTTP/1.1 ") else -1)
        except OSError:
            answers.append(-1)


def _attack(kind: str, port: int, path: str, key: str, duration_s: float, out: Any) -> None:
    """``ATTACKERS`` threads of one attack for ``duration_s``; their answers go to ``out``."""
    stop_at = time.monotonic() + duration_s
    answers: list[int] = []
    threads = [
        threading.Thread(
            target=_flood_one if kind == "header flood" else _trickle_one,
            args=(port, stop_at, answers)
            if kind == "header flood"
            else (port, path, key, stop_at, answers),
            daemon=True,
        )
        for _ in range(ATTACKERS)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=max(0.0, stop_at - time.monotonic()) + 5)
    out.put(answers)


def reads_under_attack(
    kind: str,
    port: int,
    *,
    pid: int,
    ids: list[str],
    admin_key: str,
    read_key: str,
    clients: int,
    duration_s: float,
) -> tuple[LoadResult, str]:
    """The readers of :func:`run_reads` while six clients run ``kind`` (a separate process)."""
    ctx = multiprocessing.get_context("fork")
    out = ctx.Queue()
    path = f"/v1/spacecraft/{ids[0]}/telemetry"
    attacker = ctx.Process(
        target=_attack, args=(kind, port, path, admin_key, duration_s + 1, out), daemon=True
    )
    attacker.start()
    time.sleep(1.0)  # the attack is under way when the readers start
    try:
        result = run_reads(
            port, pid=pid, ids=ids, read_key=read_key, clients=clients, duration_s=duration_s
        )
        try:
            answers: list[int] = out.get(timeout=30)
        except queue.Empty:
            answers = []
    finally:
        attacker.terminate()
        attacker.join(timeout=10)
    tally = ", ".join(
        f"{n} × {'no answer' if code == -1 else code}"
        for code, n in sorted(collections.Counter(answers).items())
    )
    return result, tally or "none finished"


@dataclass
class ReadsRound:
    label: str
    quiet: LoadResult
    attacked: dict[str, tuple[LoadResult, str]] = field(default_factory=dict)


def _reads_round(
    repo: Path,
    label: str,
    tmp: Path,
    args: argparse.Namespace,
    workers: int = 1,
    extra_env: dict[str, str] | None = None,
) -> ReadsRound:
    admin_key = "load-" + secrets.token_hex(16)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    db = tmp / f"reads-{secrets.token_hex(4)}.sqlite"
    proc = start_server(
        db, port, admin_key, tmp / "server.log", repo=repo, workers=workers, extra_env=extra_env
    )
    reads = {"clients": args.clients, "duration_s": args.duration}
    try:
        wait_healthy(url, proc)
        ids, _jobs, read_key = prepare(url, admin_key, args.spacecraft)
        # warm-up: fills the key and document caches, like any server that has been running
        run_reads(
            port, pid=proc.pid, ids=ids, read_key=read_key, clients=args.clients, duration_s=2
        )
        out = ReadsRound(label, run_reads(port, pid=proc.pid, ids=ids, read_key=read_key, **reads))
        for kind in ATTACKS if args.attacks else ():
            out.attacked[kind] = reads_under_attack(
                kind, port, pid=proc.pid, ids=ids, admin_key=admin_key, read_key=read_key, **reads
            )
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return out


def _servers(args: argparse.Namespace, tmp: Path) -> list[tuple[str, Path, int, dict[str, str]]]:
    """(label, checkout, workers, environment) of every server measured; peers checked out."""
    servers: list[tuple[str, Path, int, dict[str, str]]] = []
    for i, rev in enumerate(args.compare_with):
        other = tmp / f"peer-{i}"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(other), rev],
            check=True,
            capture_output=True,
        )
        servers.append((f"`{rev}`", other, 1, {}))
    for protocol in args.protocols.split(","):
        env = {"ORBITCAL_HTTP_PROTOCOL": protocol}
        servers.append((f"this checkout ({protocol})", REPO, 1, env))
        if args.workers > 1:
            servers.append(
                (f"this checkout ({protocol}), {args.workers} workers", REPO, args.workers, env)
            )
    return servers


def reads_main(args: argparse.Namespace) -> list[ReadsRound]:
    """Calibration reads only: every server of :func:`_servers` in alternating rounds."""
    rounds: list[ReadsRound] = []
    with tempfile.TemporaryDirectory(prefix="orbitcal-reads-") as tmp_name:
        tmp = Path(tmp_name)
        servers = []
        try:
            servers = _servers(args, tmp)
            for _ in range(args.rounds):
                for label, repo, workers, env in servers:
                    rounds.append(_reads_round(repo, label, tmp, args, workers, env))
        finally:
            for i in range(len(args.compare_with)):
                subprocess.run(
                    [
                        "git",
                        "-C",
                        str(REPO),
                        "worktree",
                        "remove",
                        "--force",
                        str(tmp / f"peer-{i}"),
                    ],
                    check=False,
                    capture_output=True,
                )
    return rounds


def _row(label: str, r: LoadResult, extra: str = "") -> str:
    n = max(1, r.requests)
    return (
        f"| {label} | {r.requests / r.duration_s:.0f} | {r.percentile_ms('calibration', 50):.2f} | "
        f"{r.percentile_ms('calibration', 99):.2f} | {1e3 * r.server_cpu_s / n:.3f} | "
        f"{1e3 * r.client_cpu_s / n:.3f} | {r.load_average:.1f} | {len(r.errors)} |{extra}"
    )


def reads_tables(rounds: list[ReadsRound]) -> str:
    """The quiet table, and (with ``--attacks``) the readers' figures under each attack."""
    head = (
        "| server | requests/s | p50 [ms] | p99 [ms] | server CPU / request [ms] | "
        "client CPU / request [ms] | load average | errors |"
    )
    lines = [head, "|---|---|---|---|---|---|---|---|"]
    lines += [_row(r.label, r.quiet) for r in rounds]
    if any(r.attacked for r in rounds):
        lines += [
            "",
            f"The same readers while {ATTACKERS} other clients attack (same servers, same rounds): "
            "*slow bodies* = uploads sending one byte every 0.5 s (under the idle limit), "
            "*header flood* = requests with a 32 MiB header value, one after another; "
            "the attackers' answers in the last column.",
            "",
            head.replace("| server |", "| server | attack |") + " attackers' answers |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rounds:
            for kind, (res, tally) in r.attacked.items():
                lines.append(_row(f"{r.label} | {kind}", res, f" {tally} |"))
    return "\n".join(lines)


def _median(values: list[float]) -> float:
    return float(np.median(values)) if values else float("nan")


def readme_figure(rounds: list[ReadsRound], *, ours: str, peer: str | None) -> str:
    """The README's cell: this checkout's median p99 and requests/s, the peer's in the same run."""

    def stats(label: str) -> tuple[float, float, dict[str, float]]:
        mine = [r for r in rounds if r.label == label]
        rate = _median([r.quiet.requests / r.quiet.duration_s for r in mine])
        p99 = _median([r.quiet.percentile_ms("calibration", 99) for r in mine])
        attacked = {
            kind: _median([r.attacked[kind][0].percentile_ms("calibration", 99) for r in mine])
            for kind in ATTACKS
            if all(kind in r.attacked for r in mine)
        }
        return rate, p99, attacked

    rate, p99, attacked = stats(ours)
    text = f"p99 {p99:.1f} ms, {rate:,.0f} req/s"
    if attacked:
        text += "; p99 " + ", ".join(f"{v:.1f} ms under {k}" for k, v in attacked.items())
    if peer is not None:
        peer_rate, peer_p99, _ = stats(peer)
        text += (
            f" ({rate / peer_rate:.2f}× the req/s of {peer.strip('`')}, whose p99 was "
            f"{peer_p99:.1f} ms in the same run)"
        )
    return text + " (median of rounds, `benchmarks/load.py --reads-only`)"


README_BEGIN = "<!-- load_reads -->"
README_END = "<!-- /load_reads -->"


def update_readme(figure: str, readme: Path = REPO / "README.md") -> None:
    """Rewrite the text between the README's ``load_reads`` markers."""
    text = readme.read_text()
    start, end = text.index(README_BEGIN) + len(README_BEGIN), text.index(README_END)
    readme.write_text(text[:start] + figure + text[end:])


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    mem = psutil.virtual_memory().total / 2**30
    return (
        f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB RAM, {platform.system()} "
        f"{platform.release()}, Python {platform.python_version()}; load average at start "
        f"{os.getloadavg()[0]:.1f} (the machine is shared)"
    )


def report(result: LoadResult, *, warmup_s: float) -> str:
    first, last, growth = result.rss_growth_mb(warmup_s)
    lines = [
        f"- {result.clients} concurrent clients for {result.duration_s:.0f} s: "
        f"{result.requests} requests ({result.requests / result.duration_s:.0f} requests/s), "
        f"{result.samples_ingested} samples ingested "
        f"({result.samples_ingested / result.duration_s:.0f} samples/s), "
        f"errors: {len(result.errors)}",
        f"- latency, all requests: p50 {result.all_latencies_ms(50):.1f} ms, "
        f"p99 {result.all_latencies_ms(99):.1f} ms",
        "",
        "| request | count | p50 [ms] | p99 [ms] |",
        "|---|---|---|---|",
    ]
    for kind in KINDS:
        lines.append(
            f"| {kind} | {result.counts.get(kind, 0)} | {result.percentile_ms(kind, 50):.1f} | "
            f"{result.percentile_ms(kind, 99):.1f} |"
        )
    lines += [
        "",
        f"Server RSS after a {warmup_s:g} s warm-up: median {first:.1f} MB over the first third, "
        f"{last:.1f} MB over the last third (growth {growth:+.1f} MB).",
        "",
        "| t [s] | RSS [MB] |",
        "|---|---|",
    ]
    step = max(1, len(result.rss_mb) // 20)
    lines += [f"| {t:.0f} | {r:.1f} |" for t, r in result.rss_mb[::step]]
    return "\n".join(lines)


def reads_only(args: argparse.Namespace) -> None:
    """``--reads-only``: run, write ``--out`` (and the README's figure with ``--readme``)."""
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    where = machine()
    rounds = reads_main(args)
    command = (
        f"python benchmarks/load.py --reads-only --duration {args.duration:g} "
        f"--clients {args.clients} --spacecraft {args.spacecraft} --rounds {args.rounds}"
        + "".join(f" --compare-with {rev}" for rev in args.compare_with)
        + (f" --protocols {args.protocols}" if args.protocols != "httptools,h11" else "")
        + (f" --workers {args.workers}" if args.workers > 1 else "")
        + (" --attacks" if args.attacks else "")
        + (" --readme" if args.readme else "")
    )
    ours = f"this checkout ({args.protocols.split(',')[0]})"
    peer = f"`{args.compare_with[0]}`" if args.compare_with else None
    figure = readme_figure(rounds, ours=ours, peer=peer)
    text = "\n".join(
        [
            "# Reads under load: `GET /v1/spacecraft/{id}/calibration` (`benchmarks/load.py`)",
            "",
            f"Machine: {where}.",
            f"Run: `{command}` from {started}; `orbitcal serve` (one process, or `--workers N`; "
            "`this checkout (P)` runs with `ORBITCAL_HTTP_PROTOCOL=P`), SQLite; clients in one "
            "process (raw HTTP/1.1 keep-alive, closed loop) on the same 2 cores as the server; "
            "servers measured in alternating rounds. Load average at the end of each run in its "
            "row: the machine is shared, so compare rows of one run, not runs.",
            "",
            reads_tables(rounds),
            "",
            f"Summary ({ours}, the README's figure): {figure}.",
            "",
        ]
    )
    args.out.write_text(text)
    if args.readme:
        update_readme(figure)
    print(text)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=300.0, help="seconds of load (default 300)")
    p.add_argument("--clients", type=int, default=50)
    p.add_argument("--spacecraft", type=int, default=5)
    p.add_argument("--ingest-share", type=float, default=0.2)
    p.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "load.md")
    p.add_argument("--reads-only", action="store_true", help="only GET calibration, raw client")
    p.add_argument(
        "--compare-with",
        action="append",
        default=[],
        metavar="REV",
        help="--reads-only: git revision of a peer server (repeatable)",
    )
    p.add_argument("--rounds", type=int, default=2, help="--reads-only: alternating rounds")
    p.add_argument("--workers", type=int, default=1, help="--reads-only: also N API processes")
    p.add_argument(
        "--protocols",
        default="httptools,h11",
        help="--reads-only: ORBITCAL_HTTP_PROTOCOL values this checkout runs with (first: the "
        "README's figure)",
    )
    p.add_argument(
        "--attacks",
        action="store_true",
        help="--reads-only: also measure the readers while six clients trickle bodies, then "
        "while six send 32 MiB header values",
    )
    p.add_argument(
        "--readme",
        action="store_true",
        help="--reads-only: write this checkout's figure into README.md (between its "
        "load_reads markers)",
    )
    args = p.parse_args()
    if args.reads_only:
        reads_only(args)
        return
    admin_key = "load-" + secrets.token_hex(16)
    with tempfile.TemporaryDirectory(prefix="orbitcal-load-") as tmp:
        port = free_port()
        url = f"http://127.0.0.1:{port}"
        proc = start_server(Path(tmp) / "load.sqlite", port, admin_key, Path(tmp) / "server.log")
        try:
            wait_healthy(url, proc)
            ids, jobs, read_key = prepare(url, admin_key, args.spacecraft)
            result = run_load(
                url,
                pid=proc.pid,
                ids=ids,
                jobs=jobs,
                admin_key=admin_key,
                read_key=read_key,
                clients=args.clients,
                duration_s=args.duration,
                ingest_share=args.ingest_share,
            )
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    text = "\n".join(
        [
            "# Load: mixed ingest and reads on loopback (`benchmarks/load.py`)",
            "",
            f"Machine: {machine()}.",
            f"Run: `python benchmarks/load.py --duration {args.duration:g} --clients "
            f"{args.clients} --spacecraft {args.spacecraft} --ingest-share {args.ingest_share:g}`"
            f" on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; `orbitcal serve` on "
            "SQLite (WAL, synchronous=FULL), clients and server on the same 2 cores.",
            "",
            report(result, warmup_s=min(30.0, args.duration / 5)),
            "",
            "Errors: " + ("; ".join(sorted(set(result.errors))[:10]) or "none") + ".",
            "",
        ]
    )
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
