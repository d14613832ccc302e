"""Service test helpers: a real uvicorn server on 127.0.0.1 (random port) per test or module."""

from __future__ import annotations

import os
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import uvicorn

from service.app import create_app
from service.settings import Settings

ADMIN_KEY = "test-admin-" + uuid.uuid4().hex
PG_URL = os.environ.get("ORBITCAL_TEST_PG", "postgresql://postgres@127.0.0.1:5432/test")


class LiveServer:
    def __init__(self, app: Any) -> None:
        self.app = app
        config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="on")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def start(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        sock = self.server.servers[0].sockets[0]
        self.port = sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}"
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=30)

    def client(self, key: str | None = ADMIN_KEY) -> httpx.Client:
        headers = {"X-API-Key": key} if key else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=60)


@contextmanager
def live_server(settings: Settings, **kwargs: Any) -> Iterator[LiveServer]:
    server = LiveServer(create_app(settings, **kwargs)).start()
    try:
        yield server
    finally:
        server.stop()


def sqlite_settings(tmp_path: Path, **overrides: Any) -> Settings:
    values: dict[str, Any] = {
        "database_url": f"sqlite:///{tmp_path / 'orbitcal.sqlite'}",
        "admin_key": ADMIN_KEY,
        "scheduler": False,
        "sqlite_synchronous": "NORMAL",
        "log_level": "WARNING",
    }
    values.update(overrides)
    return Settings(**values)


@contextmanager
def pg_schema_url() -> Iterator[str]:
    """A fresh PostgreSQL schema for this test run; dropped afterwards."""
    import sqlalchemy as sa

    from service.storage import make_engine

    schema = "t_" + uuid.uuid4().hex[:12]
    admin = make_engine(PG_URL)
    with admin.begin() as conn:
        conn.exec_driver_sql(f"CREATE SCHEMA {schema}")
    sep = "&" if "?" in PG_URL else "?"
    try:
        yield f"{PG_URL}{sep}options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(sa.text(f"DROP SCHEMA IF EXISTS {schema} CASCADE"))
        admin.dispose()


def wait_job(client: httpx.Client, job_id: str, *, timeout_s: float = 120.0) -> dict[str, Any]:
    """Poll ``GET /v1/jobs/{id}`` until it finishes (bounded)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in ("succeeded", "failed"):
            return job  # type: ignore[no-any-return]
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} did not finish in {timeout_s} s")


def wait_versions(
    client: httpx.Client, spacecraft: str, n: int, *, timeout_s: float = 120.0
) -> list[dict[str, Any]]:
    """Poll the version list until it holds ``n`` versions and no job is live (bounded)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        versions = client.get(f"/v1/spacecraft/{spacecraft}/calibrations").json()
        if len(versions) >= n:
            return versions  # type: ignore[no-any-return]
        time.sleep(0.2)
    raise AssertionError(f"{spacecraft} did not reach {n} calibration versions in {timeout_s} s")


def encode_all_formats(df: Any) -> list[tuple[bytes, str]]:
    """The table split in five consecutive parts: CSV, NDJSON, JSON, Parquet, CCSDS packets."""
    import io

    import numpy as np

    from orbitcal import ccsds

    bodies = []
    parts = np.array_split(np.arange(len(df)), 5)
    for fmt, idx in zip(("csv", "ndjson", "json", "parquet", "ccsds"), parts, strict=True):
        part = df.iloc[idx]
        if fmt == "csv":
            bodies.append((part.to_csv(index=False).encode(), "text/csv"))
        elif fmt == "ndjson":
            text = part.to_json(orient="records", lines=True, double_precision=15)
            bodies.append((text.encode(), "application/x-ndjson"))
        elif fmt == "json":
            text = part.to_json(orient="records", double_precision=15)
            bodies.append((text.encode(), "application/json"))
        elif fmt == "parquet":
            buf = io.BytesIO()
            part.to_parquet(buf, index=False)
            bodies.append((buf.getvalue(), "application/vnd.apache.parquet"))
        else:
            packets = ccsds.encode_packets(
                part["time"].to_numpy(),
                part[["b_x", "b_y", "b_z"]].to_numpy(),
                q_wxyz=part[["q_w", "q_x", "q_y", "q_z"]].to_numpy(),
            )
            bodies.append((packets, "application/vnd.ccsds.space-packet"))
    return bodies
