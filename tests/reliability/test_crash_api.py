"""``kill -9`` of the API during sustained ingest, repeated: every acknowledged sample is stored
exactly once, and every unacknowledged batch is either wholly stored or wholly absent.

The server is the real ``orbitcal serve`` command (``orbitcal.cli.main(["serve", ...])``) on an
SQLite file, forked from a warm parent (``forkserver.py``) so that a restart costs ~1 s instead
of ~6 s of imports. Four client threads post 200-sample CSV batches with unique times without
pause; the test kills the server with SIGKILL at a random moment of each life (0.2–0.8 s after its
first acknowledged upload), 20 times, then inspects the SQLite file directly.
"""

from __future__ import annotations

import os
import random
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
import pytest
from reliability_helpers import (
    ADMIN_KEY,
    CSV,
    T0_UTC_S,
    csv_batch,
    fork_server,
    free_port,
    kill9,
    sqlite_query,
    stored_times_us,
    wait_healthy,
)

KILLS = int(os.environ.get("RELIABILITY_KILLS", "20"))
BATCH = 200  # samples per upload
CLIENTS = 4
#: Client c's batch k starts at T0 + (c * 1e6 + k * BATCH) s: 1 s apart, never overlapping.
CLIENT_SPAN_S = 1_000_000


def batch_t0(client: int, k: int) -> float:
    return T0_UTC_S + client * CLIENT_SPAN_S + k * BATCH


@dataclass
class ClientLog:
    acked: dict[int, int] = field(default_factory=dict)  # batch -> accepted (200 answers)
    unacked: set[int] = field(default_factory=set)  # sent, no answer (connection died)
    refused: set[int] = field(default_factory=set)  # connection refused: never reached a server
    other: list[tuple[int, int, str]] = field(default_factory=list)  # unexpected statuses


def _client(c: int, url: str, stop: threading.Event, log: ClientLog) -> None:
    k = 0
    with httpx.Client(base_url=url, headers={"X-API-Key": ADMIN_KEY, **CSV}, timeout=30) as http:
        while not stop.is_set():
            body = csv_batch(batch_t0(c, k), BATCH, seed=c * 100_000 + k)
            try:
                r = http.post("/v1/spacecraft/crash-1/telemetry", content=body)
            except httpx.ConnectError:
                log.refused.add(k)
                time.sleep(0.05)
            except httpx.TransportError:
                log.unacked.add(k)
            else:
                if r.status_code == 200:
                    log.acked[k] = r.json()["accepted"]
                else:
                    log.other.append((k, r.status_code, r.text[:200]))
            k += 1


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_kill_9_during_ingest_loses_no_acknowledged_sample(tmp_path: Path) -> None:
    db = tmp_path / "crash.sqlite"
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    argv = ["serve", "--port", str(port), "--database", f"sqlite:///{db}", "--no-scheduler"]
    env = {"ORBITCAL_ADMIN_KEY": ADMIN_KEY, "ORBITCAL_LOG_LEVEL": "WARNING"}
    rng = random.Random(6)
    logs = [ClientLog() for _ in range(CLIENTS)]
    stop = threading.Event()
    startup_s: list[float] = []
    acked_per_life: list[int] = []
    first_ack_s: list[float] = []
    with fork_server(tmp_path) as fs:
        pid = fs.spawn({"kind": "cli", "argv": argv, "env": env})
        startup_s.append(wait_healthy(url, pid=pid))
        r = httpx.post(
            url + "/v1/spacecraft", json={"id": "crash-1"}, headers={"X-API-Key": ADMIN_KEY}
        )
        assert r.status_code == 201, r.text
        threads = [
            threading.Thread(target=_client, args=(c, url, stop, logs[c]), daemon=True)
            for c in range(CLIENTS)
        ]
        for t in threads:
            t.start()
        try:
            for _life in range(KILLS):
                before = sum(len(lg.acked) for lg in logs)
                t_life = time.monotonic()
                while sum(len(lg.acked) for lg in logs) == before:  # ingest is flowing
                    assert time.monotonic() - t_life < 60, "no upload acknowledged in 60 s"
                    time.sleep(0.01)
                first_ack_s.append(time.monotonic() - t_life)
                time.sleep(rng.uniform(0.2, 0.8))
                kill9(pid)
                acked_per_life.append(sum(len(lg.acked) for lg in logs) - before)
                pid = fs.spawn({"kind": "cli", "argv": argv, "env": env})
                startup_s.append(wait_healthy(url, pid=pid))
            time.sleep(0.5)  # the last life ends cleanly: clients stop, then the server
        finally:
            stop.set()
            for t in threads:
                t.join(timeout=60)
        # Retrying every unacknowledged batch is safe: each sample is stored once either way.
        retry_accepted = retry_duplicates = 0
        retried = 0
        with httpx.Client(base_url=url, headers={"X-API-Key": ADMIN_KEY, **CSV}) as http:
            stored_before_retry = stored_times_us(db, "crash-1")
            for c, lg in enumerate(logs):
                for k in sorted(lg.unacked):
                    body = csv_batch(batch_t0(c, k), BATCH, seed=c * 100_000 + k)
                    r = http.post("/v1/spacecraft/crash-1/telemetry", content=body)
                    assert r.status_code == 200, r.text
                    retry_accepted += r.json()["accepted"]
                    retry_duplicates += r.json()["duplicates"]
                    retried += 1
        kill9(pid)

    for lg in logs:
        assert lg.other == [], f"unexpected answers during ingest: {lg.other[:5]}"
    assert len(startup_s) == KILLS + 1
    # Every life served uploads, so the kills landed during sustained ingest.
    assert min(acked_per_life) >= 1, acked_per_life

    # Inspect the file a killed process left behind (before the retries above, and after).
    def by_batch(times_us: np.ndarray) -> dict[tuple[int, int], int]:
        off = np.rint(times_us / 1e6 - T0_UTC_S).astype(np.int64)
        client, rest = np.divmod(off, CLIENT_SPAN_S)
        keys, counts = np.unique(
            np.stack([client, rest // BATCH], axis=1), axis=0, return_counts=True
        )
        return {(int(a), int(b)): int(n) for (a, b), n in zip(keys, counts, strict=True)}

    stored = by_batch(stored_before_retry)
    assert len(np.unique(stored_before_retry)) == len(stored_before_retry)
    acked_total = 0
    committed_unacked = 0
    for c, lg in enumerate(logs):
        for k, accepted in lg.acked.items():
            assert accepted == BATCH, (c, k, accepted)  # unique times: all new on first ack
            assert stored.get((c, k)) == BATCH, f"acknowledged batch {c}/{k} not fully stored"
            acked_total += 1
        for k in lg.unacked | lg.refused:
            n = stored.get((c, k), 0)
            assert n in (0, BATCH), f"unacknowledged batch {c}/{k} half-written: {n} rows"
            committed_unacked += n == BATCH
        assert lg.refused.isdisjoint(k for (cc, k) in stored if cc == c)  # refused = never stored
    # Nothing stored that no client sent.
    sent = {(c, k) for c, lg in enumerate(logs) for k in (*lg.acked, *lg.unacked)}
    assert set(stored) <= sent
    assert retry_accepted + retry_duplicates == BATCH * retried
    assert retry_duplicates == BATCH * committed_unacked

    after = stored_times_us(db, "crash-1")
    assert len(np.unique(after)) == len(after) == BATCH * (acked_total + retried)
    [(count,)] = sqlite_query(db, "SELECT sample_count FROM spacecraft WHERE id = 'crash-1'")
    assert count == len(after)  # the counter is updated in the ingest transaction
    assert sqlite_query(db, "PRAGMA integrity_check") == [("ok",)]
    print(
        f"\n{KILLS} kills: {acked_total} acked batches ({BATCH * acked_total} samples), "
        f"{retried} unacked (of which {committed_unacked} committed before the kill), "
        f"acked per life min/median {min(acked_per_life)}/{int(np.median(acked_per_life))}, "
        f"restart to healthy median {np.median(startup_s[1:]):.2f} s, "
        f"healthy to first ack median {np.median(first_ack_s):.2f} s"
    )
