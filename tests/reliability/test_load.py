"""A short, bounded run of ``benchmarks/load.py``: 50 concurrent clients, mixed ingest and reads,
for 12 s on loopback against ``orbitcal serve`` in its own process. No request may fail, every
acknowledged sample must be stored, and the server's memory must not grow (the long run and its
figures are in ``benchmarks/results/load.md``)."""

from __future__ import annotations

import importlib.util
import secrets
import sqlite3
import sys
from pathlib import Path
from types import ModuleType

import pytest
from reliability_helpers import REPO

CLIENTS = 50
DURATION_S = 12.0
WARMUP_S = 5.0
#: Allowed RSS growth between the first and the last third of the run [MB]: allocator noise
#: (~1-5 MB measured), far below what a leak of one batch per request (~7 kB x 1000s) would add.
MAX_GROWTH_MB = 20.0


def _load_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("orbitcal_load", REPO / "benchmarks" / "load.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it executes
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_50_clients_mixed_load_without_error_or_memory_growth(tmp_path: Path) -> None:
    load = _load_module()
    admin_key = "load-" + secrets.token_hex(16)
    port = load.free_port()
    url = f"http://127.0.0.1:{port}"
    db = tmp_path / "load.sqlite"
    proc = load.start_server(db, port, admin_key, tmp_path / "server.log")
    try:
        load.wait_healthy(url, proc)
        ids, jobs, read_key = load.prepare(url, admin_key, 2)
        result = load.run_load(
            url,
            pid=proc.pid,
            ids=ids,
            jobs=jobs,
            admin_key=admin_key,
            read_key=read_key,
            clients=CLIENTS,
            duration_s=DURATION_S,
        )
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    print("\n" + load.report(result, warmup_s=WARMUP_S))
    assert result.errors == [], sorted(set(result.errors))[:10]
    assert set(result.counts) == set(load.KINDS), result.counts  # every kind was exercised
    assert result.requests / result.duration_s > 20, "throughput collapsed"
    assert result.all_latencies_ms(99) < 10_000, "p99 latency above 10 s"
    first, last, growth = result.rss_growth_mb(WARMUP_S)
    assert growth < MAX_GROWTH_MB, f"server RSS grew {first:.1f} -> {last:.1f} MB"
    con = sqlite3.connect(db)
    [(stored,)] = con.execute("SELECT COUNT(*) FROM samples")
    con.close()
    assert stored == 600 * len(ids) + result.samples_ingested  # every acknowledged sample
    assert result.samples_ingested == load.INGEST_ROWS * result.counts["ingest"]
