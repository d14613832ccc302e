"""Ingest and read benchmark of the service on the embedded default (SQLite WAL).

Side by side in one run, on the same machine and schema:

* raw: ``executemany`` of pre-built row tuples into the service's ``samples`` table (the same
  ``INSERT ... ON CONFLICT DO NOTHING`` and one commit per batch, as the service does);
* HTTP: ``orbitcal serve`` in a separate process on loopback, one client posting batches of
  10^4 rows as CSV, Parquet and CCSDS packets (each batch parsed, validated, committed before 200);
* ``GET /v1/spacecraft/{id}/calibration`` latency with 50 concurrent clients, closed loop (each
  sends its next request when the previous answer arrives) and paced (each client 5 requests/s).

Usage: ``python benchmarks/ingest.py [--batches 20] [--out benchmarks/results/ingest.md]``.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import os
import platform
import secrets
import socket
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import pandas as pd

from orbitcal import ccsds

BATCH = 10_000
T0 = 1_700_000_000.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _frame(batch: int, rng: np.random.Generator) -> pd.DataFrame:
    t = T0 + (batch * BATCH + np.arange(BATCH)) * 0.1
    q = rng.normal(size=(BATCH, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    b = rng.normal(0, 3e4, (BATCH, 3))
    return pd.DataFrame(
        {
            "time": t,
            "b_x": b[:, 0],
            "b_y": b[:, 1],
            "b_z": b[:, 2],
            "q_w": q[:, 0],
            "q_x": q[:, 1],
            "q_y": q[:, 2],
            "q_z": q[:, 3],
        }
    )


def _encode(df: pd.DataFrame, fmt: str) -> tuple[bytes, str]:
    if fmt == "csv":
        return df.to_csv(index=False).encode(), "text/csv"
    if fmt == "parquet":
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        return buf.getvalue(), "application/vnd.apache.parquet"
    q = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    body = ccsds.encode_packets(
        df["time"].to_numpy(), df[["b_x", "b_y", "b_z"]].to_numpy(), q_wxyz=q
    )
    return body, "application/vnd.ccsds.space-packet"


def raw_executemany(db: Path, frames: list[pd.DataFrame], synchronous: str) -> float:
    """Samples/s of executemany into the service schema (rows pre-built, one commit per batch)."""
    from service.ingest import telemetry_to_rows
    from service.storage import _insert_sql, make_engine, upgrade

    upgrade(make_engine(f"sqlite:///{db}"))
    con = sqlite3.connect(db, isolation_level=None)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute(f"PRAGMA synchronous={synchronous}")
    con.execute(
        "INSERT INTO spacecraft (id, attitude_frame, created_at, sample_count, samples_at_last_job)"
        " VALUES ('raw', 'GCRS', 0, 0, 0)"
    )
    pk = con.execute("SELECT pk FROM spacecraft WHERE id = 'raw'").fetchone()[0]
    from orbitcal.telemetry import Telemetry

    batches = [
        telemetry_to_rows(
            pk,
            Telemetry(
                t_utc_s=f["time"].to_numpy(),
                b_raw_nt=f[["b_x", "b_y", "b_z"]].to_numpy(),
                q_wxyz=f[["q_w", "q_x", "q_y", "q_z"]].to_numpy(),
            ),
        )
        for f in frames
    ]
    sql = _insert_sql("sqlite")
    t0 = time.perf_counter()
    for rows in batches:
        con.execute("BEGIN IMMEDIATE")
        con.executemany(sql, rows)
        con.execute(
            "UPDATE spacecraft SET sample_count = sample_count + ? WHERE pk = ?", (len(rows), pk)
        )
        con.execute("COMMIT")
    elapsed = time.perf_counter() - t0
    con.close()
    return len(frames) * BATCH / elapsed


def http_ingest(
    url: str, key: str, sc: str, bodies: list[tuple[bytes, str]]
) -> tuple[float, list[float]]:
    lat = []
    with httpx.Client(base_url=url, headers={"X-API-Key": key}, timeout=120) as c:
        assert c.post("/v1/spacecraft", json={"id": sc}).status_code == 201
        t0 = time.perf_counter()
        for body, media in bodies:
            t1 = time.perf_counter()
            r = c.post(
                f"/v1/spacecraft/{sc}/telemetry", content=body, headers={"content-type": media}
            )
            lat.append(time.perf_counter() - t1)
            assert r.status_code == 200 and r.json()["accepted"] == BATCH, r.text[:300]
        elapsed = time.perf_counter() - t0
    return len(bodies) * BATCH / elapsed, lat


async def _reader(port: int, request: bytes, n: int, pace_s: float, out: list[float]) -> None:
    """One keep-alive HTTP/1.1 connection sending ``n`` GETs (a minimal client, so that the
    measurement is the server's, not a client library's)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    if pace_s:  # independent clients: start at random phases, not in one burst
        await asyncio.sleep(
            float(np.random.default_rng(len(out) + id(writer) % 997).uniform(0, pace_s))
        )
    try:
        for i in range(n + 1):  # the first request warms the connection up and is not counted
            t0 = time.perf_counter()
            writer.write(request)
            await writer.drain()
            head = await reader.readuntil(b"\r\n\r\n")
            status = int(head.split(b" ", 2)[1])
            length = 0
            for line in head.split(b"\r\n"):
                if line.lower().startswith(b"content-length:"):
                    length = int(line.split(b":", 1)[1])
            await reader.readexactly(length)
            dt = time.perf_counter() - t0
            assert status == 200, status
            if i:
                out.append(dt)
            if pace_s:
                await asyncio.sleep(max(0.0, pace_s - dt))
    finally:
        writer.close()


async def read_latency(
    port: int, key: str, sc: str, clients: int, per_client: int, pace_s: float
) -> dict[str, float]:
    lat: list[float] = []
    request = (
        f"GET /v1/spacecraft/{sc}/calibration HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"X-API-Key: {key}\r\n\r\n"
    ).encode()
    t0 = time.perf_counter()
    await asyncio.gather(*(_reader(port, request, per_client, pace_s, lat) for _ in range(clients)))
    elapsed = time.perf_counter() - t0
    ms = np.array(lat) * 1e3
    return {
        "requests": float(ms.size),
        "rate": ms.size / elapsed,
        "p50": float(np.percentile(ms, 50)),
        "p99": float(np.percentile(ms, 99)),
        "max": float(ms.max()),
    }


def _insert_calibration(db: Path, sc: str) -> None:
    con = sqlite3.connect(db)
    pk = con.execute("SELECT pk FROM spacecraft WHERE id = ?", (sc,)).fetchone()[0]
    doc = {
        "spacecraft": sc,
        "version": 1,
        "method": "linear",
        "created_at": "2026-01-01T00:00:00Z",
        "reference_field": "IGRF-14",
        "data": {"start": "2023-11-14T22:13:20Z", "end": "2023-11-15T04:00:00Z", "n": 200000},
        "metrics": {"holdout_rms_nt": 2.0},
        "linear": {"M": np.eye(3).tolist(), "o": [1.0, 2.0, 3.0]},
        "model": {
            "form": "b_cal = M @ (b_raw - o - K @ x_hk)",
            "M": np.eye(3).tolist(),
            "o": [1.0, 2.0, 3.0],
        },
    }
    import json

    con.execute(
        "INSERT INTO calibrations (spacecraft_pk, version, status, reason, created_at, job_id, "
        "holdout_rms_nt, document, provenance) "
        "VALUES (?, 1, 'in_service', 'benchmark', 0, NULL, 2.0, ?, '{}')",
        (pk, json.dumps(doc)),
    )
    con.commit()
    con.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, default=20, help="batches of 10^4 rows per format")
    ap.add_argument("--synchronous", default="FULL", choices=("FULL", "NORMAL"))
    ap.add_argument("--out", type=Path, default=None, help="write a Markdown summary here")
    args = ap.parse_args()
    load_before = os.getloadavg()[0]
    rng = np.random.default_rng(0)
    frames = [_frame(i, rng) for i in range(args.batches)]
    work = Path(tempfile.mkdtemp(prefix="orbitcal-bench-"))
    lines: list[str] = []

    def say(s: str = "") -> None:
        print(s, flush=True)
        lines.append(s)

    # raw is measured before and after the HTTP runs (the machine is shared: load drifts)
    raw_before = raw_executemany(work / "raw1.sqlite", frames, args.synchronous)
    db = work / "service.sqlite"
    key = "bench_" + secrets.token_urlsafe(24)
    port = _free_port()
    env = {
        **os.environ,
        "ORBITCAL_ADMIN_KEY": key,
        "ORBITCAL_SQLITE_SYNCHRONOUS": args.synchronous,
        "ORBITCAL_SCHEDULER": "false",
        "ORBITCAL_RATE_LIMIT_PER_S": "0",  # measure the service, not the limiter
        "ORBITCAL_LOG_LEVEL": "WARNING",
    }
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orbitcal",
            "serve",
            "--port",
            str(port),
            "--database",
            f"sqlite:///{db}",
        ],
        env=env,
        stderr=subprocess.DEVNULL,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(200):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        results: dict[str, tuple[float, list[float]]] = {}
        for fmt in ("csv", "parquet", "ccsds"):
            bodies = [_encode(f, fmt) for f in frames]
            results[fmt] = http_ingest(url, key, f"bench-{fmt}", bodies)
        _insert_calibration(db, "bench-csv")
        # a read-only key, as a ground-segment client would hold
        with httpx.Client(base_url=url, headers={"X-API-Key": key}) as c:
            reader_key = c.post("/v1/keys", json={"name": "bench", "scopes": ["read:*"]}).json()[
                "key"
            ]
        closed = asyncio.run(read_latency(port, reader_key, "bench-csv", 50, 40, 0.0))
        paced = asyncio.run(read_latency(port, reader_key, "bench-csv", 50, 25, 0.2))
    finally:
        server.terminate()
        server.wait(timeout=30)
    raw_after = raw_executemany(work / "raw2.sqlite", frames, args.synchronous)
    raw = 0.5 * (raw_before + raw_after)

    say(
        f"machine: {platform.machine()}, {os.cpu_count()} cores ({_cpu()}), shared; 1-min load "
        f"average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after the run; "
        f"Python {platform.python_version()}; SQLite "
        f"{sqlite3.sqlite_version}, WAL, synchronous={args.synchronous}"
    )
    say(f"batches: {args.batches} × {BATCH} rows per format (time, b, q); one client, sequential")
    say()
    say("| path | samples/s | vs raw | batch latency p50 / max [ms] |")
    say("|---|---:|---:|---:|")
    say(
        f"| raw executemany (same schema, same SQL, 1 commit per batch; mean of "
        f"{raw_before:,.0f} before and {raw_after:,.0f} after) | {raw:,.0f} | 100 % | – |"
    )
    for fmt, (rate, lat) in results.items():
        ms = np.array(lat) * 1e3
        say(
            f"| HTTP {fmt} | {rate:,.0f} | {100 * rate / raw:.0f} % | "
            f"{statistics.median(ms):.0f} / {ms.max():.0f} |"
        )
    say()
    say("GET /v1/spacecraft/{id}/calibration, 50 concurrent keep-alive connections, read-only key:")
    say()
    say("| load | requests | req/s | p50 [ms] | p99 [ms] | max [ms] |")
    say("|---|---:|---:|---:|---:|---:|")
    for name, r in (("closed loop (no think time)", closed), ("paced, 5 req/s per client", paced)):
        say(
            f"| {name} | {r['requests']:.0f} | {r['rate']:.0f} | {r['p50']:.1f} | "
            f"{r['p99']:.1f} | {r['max']:.1f} |"
        )
    if args.out:
        args.out.write_text("\n".join(lines) + "\n")


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


if __name__ == "__main__":
    main()
