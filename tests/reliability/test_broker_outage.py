"""Broker unavailable: a retraining asked for while the Celery broker is down is not lost. The API
answers 202 at once, the job waits ``queued`` in the database, and the scheduler dispatches it
once the broker is back; the job then runs to completion."""

from __future__ import annotations

import sqlite3
import time
import uuid
from pathlib import Path

import pytest
from pydantic import SecretStr
from reliability_helpers import (
    ADMIN_KEY,
    CSV,
    SWARM_A_TLE,
    T0_UTC_S,
    free_port,
    live_server,
    physical_csv,
    require_service,
)

from service.jobs import InlineRunner
from service.scheduler import RESUBMIT_S, FleetScheduler
from service.settings import Settings
from service.storage import make_engine

REDIS_TEST_DB = 15  # a database number nobody else on this machine uses


def _queue_with_broker_down(db: Path) -> tuple[str, Settings, float]:
    """Register, upload, ask for a retraining with the broker down: ``(job_id, settings, s)``."""
    settings = Settings(
        database_url=f"sqlite:///{db}",
        admin_key=SecretStr(ADMIN_KEY),
        scheduler=False,
        job_backend="celery",
        broker_url=f"redis://127.0.0.1:{free_port()}/0",  # nothing listens there
        log_level="ERROR",
    )
    with live_server(settings) as server, server.client() as http:
        assert (
            http.post("/v1/spacecraft", json={"id": "b-1", "tle": SWARM_A_TLE}).status_code == 201
        )
        r = http.post(
            "/v1/spacecraft/b-1/telemetry", content=physical_csv(T0_UTC_S, 400), headers=CSV
        )
        assert r.json()["accepted"] == 400
        t0 = time.perf_counter()
        r = http.post("/v1/spacecraft/b-1/calibrations")
        answer_s = time.perf_counter() - t0
        assert r.status_code == 202, r.text
        job_id = r.json()["job_id"]
        time.sleep(0.5)
        job = http.get(f"/v1/jobs/{job_id}").json()
        assert job["status"] == "queued", job
    # The broker stays down for longer than the scheduler's patience: age the job past it.
    con = sqlite3.connect(db)
    con.execute(
        "UPDATE jobs SET created_at = created_at - ? WHERE id = ?", (RESUBMIT_S + 60, job_id)
    )
    con.commit()
    con.close()
    return job_id, settings, answer_s


def test_job_asked_for_while_the_broker_is_down_is_dispatched_later(tmp_path: Path) -> None:
    db = tmp_path / "broker.sqlite"
    job_id, settings, answer_s = _queue_with_broker_down(db)
    # The request never waits for the broker (its client alone retries for ~6 s when it is down).
    assert answer_s < 2.0, f"POST /calibrations took {answer_s:.1f} s with the broker down"
    print(f"\nPOST /calibrations with the broker down answered 202 in {answer_s:.2f} s")
    # The broker is back: here a runner that executes what the scheduler dispatches.
    engine = make_engine(settings.database_url)
    runner = InlineRunner(engine, settings)
    try:
        submitted = FleetScheduler(engine, settings, runner).tick()
        assert job_id in submitted
    finally:
        runner.shutdown()  # waits for the job
    con = sqlite3.connect(db)
    [(status, error)] = con.execute("SELECT status, error FROM jobs WHERE id = ?", (job_id,))
    [(versions,)] = con.execute("SELECT COUNT(*) FROM calibrations WHERE status = 'in_service'")
    con.close()
    engine.dispose()
    assert (status, error) == ("succeeded", None)
    assert versions == 1


@pytest.mark.services
def test_queued_job_reaches_the_real_redis_broker_when_it_is_back(tmp_path: Path) -> None:
    require_service("Redis", 6379)
    import redis

    from service.celery_app import CeleryRunner

    db = tmp_path / "broker.sqlite"
    job_id, settings, _ = _queue_with_broker_down(db)
    back = settings.model_copy(
        update={
            "broker_url": f"redis://127.0.0.1:6379/{REDIS_TEST_DB}",
            "queue": f"orbitcal-reliability-{uuid.uuid4().hex[:8]}",
        }
    )
    client = redis.Redis(host="127.0.0.1", port=6379, db=REDIS_TEST_DB)
    client.delete(back.queue)
    engine = make_engine(back.database_url)
    try:
        runner = CeleryRunner(back)
        submitted = FleetScheduler(engine, back, runner).tick()
        assert job_id in submitted
        deadline = time.monotonic() + 30  # sent by the runner's sender thread
        while not any(job_id.encode() in m for m in client.lrange(back.queue, 0, -1)):
            assert time.monotonic() < deadline, "the task message is not in Redis"
            time.sleep(0.05)
        runner.shutdown()
    finally:
        client.delete(back.queue)
        engine.dispose()
