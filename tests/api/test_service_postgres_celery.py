"""The same end-to-end path on PostgreSQL with Celery workers (Redis and RabbitMQ brokers).

Marked ``services``: needs PostgreSQL, Redis and RabbitMQ on 127.0.0.1 (CI fails if absent).
Each run uses its own PostgreSQL schema and its own Celery queue.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from conftest_services import require_service
from pydantic import SecretStr
from service_helpers import (
    ADMIN_KEY,
    encode_all_formats,
    live_server,
    pg_schema_url,
    wait_job,
    wait_versions,
)
from service_worlds import SENSOR_A, SENSOR_B, SWARM_A_TLE, T0_UTC_S, world

from orbitcal.calibrate.document import calibration_from_document
from service.settings import Settings
from service.storage import insert_samples, make_engine, upgrade, write_tx

pytestmark = pytest.mark.services

BROKERS = {
    "redis": ("Redis", 6379, "redis://127.0.0.1:6379/0"),
    "rabbitmq": ("RabbitMQ", 5672, "amqp://guest:guest@127.0.0.1:5672//"),
}


@contextmanager
def celery_worker(
    database_url: str, broker_url: str, queue: str
) -> Iterator[subprocess.Popen[bytes]]:
    env = {
        **os.environ,
        "ORBITCAL_DATABASE_URL": database_url,
        "ORBITCAL_BROKER_URL": broker_url,
        "ORBITCAL_QUEUE": queue,
        "ORBITCAL_LOG_LEVEL": "WARNING",
    }
    proc = subprocess.Popen(
        [sys.executable, "-m", "orbitcal", "worker", "--concurrency", "1"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.mark.slow  # 28 s per broker measured (load 5, 2 cores)
@pytest.mark.parametrize("broker", sorted(BROKERS))
def test_end_to_end_on_postgresql_with_celery(broker: str, tmp_path: Path) -> None:
    name, port, broker_url = BROKERS[broker]
    require_service("PostgreSQL", 5432)
    require_service(name, port)
    queue = "orbitcal-test-" + uuid.uuid4().hex[:8]
    with pg_schema_url() as url:
        settings = Settings(
            database_url=url,
            admin_key=SecretStr(ADMIN_KEY),
            job_backend="celery",
            broker_url=broker_url,
            queue=queue,
            scheduler=True,
            scheduler_tick_s=0.3,
            cadence_s=0.5,
            min_new_samples=2000,
            window_s=43200.0,
            log_level="WARNING",
        )
        with (
            live_server(settings) as server,
            celery_worker(url, broker_url, queue) as worker,
            server.client() as c,
        ):
            assert (
                c.post("/v1/spacecraft", json={"id": "swarm-a", "tle": SWARM_A_TLE}).status_code
                == 201
            )
            df, _ = world(T0_UTC_S, 4320, positions=False, seed=3)
            bodies = encode_all_formats(df)  # every format, CCSDS included
            for body, media in bodies:
                r = c.post(
                    "/v1/spacecraft/swarm-a/telemetry",
                    content=body,
                    headers={"content-type": media},
                )
                assert r.status_code == 200 and not r.json()["rejected"], r.text
            for body, media in bodies:  # duplicates change nothing
                r = c.post(
                    "/v1/spacecraft/swarm-a/telemetry",
                    content=body,
                    headers={"content-type": media},
                )
                assert r.json()["accepted"] == 0
            assert c.get("/v1/spacecraft/swarm-a").json()["samples"] == len(df)
            # the scheduler (in the API) sends the job to the Celery worker
            v1 = wait_versions(c, "swarm-a", 1, timeout_s=180)[0]
            job = wait_job(c, v1["job_id"])
            assert job["status"] == "succeeded" and job["trigger"] == "schedule", job
            doc = c.get("/v1/spacecraft/swarm-a/calibration").json()
            held, b_body = world(T0_UTC_S + 86400, 1500, sensor=SENSOR_A, seed=11)
            rms = np.sqrt(
                np.mean(
                    (
                        calibration_from_document(doc).apply(held[["b_x", "b_y", "b_z"]].to_numpy())
                        - b_body
                    )
                    ** 2
                )
            )
            assert rms < 2.3, rms  # noise floor: 2 nT per axis
            # parameter change: the scheduler's next calibration recovers
            after, _ = world(T0_UTC_S + 43200, 4320, positions=False, sensor=SENSOR_B, seed=4)
            buf = io.BytesIO()
            after.to_parquet(buf, index=False)
            c.post(
                "/v1/spacecraft/swarm-a/telemetry",
                content=buf.getvalue(),
                headers={"content-type": "application/vnd.apache.parquet"},
            )
            versions = wait_versions(c, "swarm-a", 2, timeout_s=180)
            assert wait_job(c, versions[0]["job_id"])["status"] == "succeeded"
            # the worker is another process: the API's 1 s read cache may answer v1 briefly
            for _ in range(50):
                doc2 = c.get("/v1/spacecraft/swarm-a/calibration").json()
                if doc2["version"] == 2:
                    break
                time.sleep(0.1)
            held, b_body = world(T0_UTC_S + 86400, 1500, sensor=SENSOR_B, seed=12)
            rms2 = np.sqrt(
                np.mean(
                    (
                        calibration_from_document(doc2).apply(
                            held[["b_x", "b_y", "b_z"]].to_numpy()
                        )
                        - b_body
                    )
                    ** 2
                )
            )
            assert doc2["version"] == 2 and rms2 < 10.0, rms2
            assert worker.poll() is None, worker.stderr.read() if worker.stderr else ""
        _delete_queue(settings)


def _delete_queue(settings: Settings) -> None:
    """Leave no per-run queue behind on the broker."""
    from service.celery_app import make_celery

    app = make_celery(settings)
    # an empty queue may be gone already (Redis drops empty lists)
    with app.connection_for_write() as conn, contextlib.suppress(Exception):
        conn.default_channel.queue_delete(settings.queue)


def test_bulk_insert_counts_duplicates_on_postgresql() -> None:
    require_service("PostgreSQL", 5432)
    with pg_schema_url() as url:
        engine = make_engine(url)
        upgrade(engine)
        upgrade(engine)  # idempotent
        with write_tx(engine) as conn:
            conn.exec_driver_sql(
                "INSERT INTO spacecraft (id, attitude_frame, created_at, sample_count, "
                "samples_at_last_job) VALUES ('x', 'GCRS', 0, 0, 0)"
            )
            rows = [(1, i, 1.0, 2.0, 3.0, *([None] * 11), None) for i in range(100)]
            assert insert_samples(conn, 1, rows) == 100
            assert (
                insert_samples(conn, 1, [*rows[50:], (1, 1000, 0.0, 0.0, 0.0, *([None] * 12))]) == 1
            )
            count = conn.exec_driver_sql("SELECT sample_count FROM spacecraft").scalar()
        assert count == 101
        engine.dispose()


def test_orbitcal_worker_scheduler_process_sends_due_jobs_to_the_broker(tmp_path: Path) -> None:
    """``orbitcal worker --scheduler`` (the compose file's scheduler service) as a process."""
    import redis
    import sqlalchemy as sa

    from orbitcal.telemetry import from_frame
    from service.ingest import telemetry_to_rows
    from service.storage import Job, Spacecraft

    require_service("Redis", 6379)
    url = f"sqlite:///{tmp_path / 'sched.sqlite'}"
    engine = make_engine(url)
    upgrade(engine)
    tel = from_frame(world(T0_UTC_S, 600)[0]).telemetry
    with write_tx(engine) as conn:
        conn.execute(
            sa.insert(Spacecraft).values(
                id="s", attitude_frame="GCRS", created_at=0, sample_count=0, samples_at_last_job=0
            )
        )
        insert_samples(conn, 1, telemetry_to_rows(1, tel))
    queue = "orbitcal-test-" + uuid.uuid4().hex[:8]
    env = {
        **os.environ,
        "ORBITCAL_DATABASE_URL": url,
        "ORBITCAL_BROKER_URL": "redis://127.0.0.1:6379/0",
        "ORBITCAL_QUEUE": queue,
        "ORBITCAL_SCHEDULER_TICK_S": "0.5",
        "ORBITCAL_MIN_NEW_SAMPLES": "500",
    }
    proc = subprocess.Popen(
        [sys.executable, "-m", "orbitcal", "worker", "--scheduler"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    r = redis.Redis(host="127.0.0.1", port=6379, db=0)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and r.llen(queue) == 0:
            time.sleep(0.2)
        died = proc.poll() is not None and proc.stderr is not None
        assert r.llen(queue) == 1, proc.stderr.read() if died and proc.stderr else "no message"
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        r.delete(queue)
    with engine.connect() as conn:
        jobs = conn.execute(sa.select(Job.status, Job.trigger)).all()
    engine.dispose()
    assert [tuple(j) for j in jobs] == [("queued", "schedule")]
