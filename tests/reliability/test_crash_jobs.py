"""``kill -9`` of the process running a retraining: the job ends ``failed`` (never stuck
``running``), the served calibration is unchanged, the spacecraft's retraining lock is released
and the next retraining runs.

Two real processes are killed mid-fit (the fit sleeps first, so the kill lands inside it):
the API process of the embedded default (inline jobs), and a worker process running the job
function that Celery workers run (``service.jobs.run_retrain``), whose message Celery redelivers
after a worker loss (``task_acks_late`` + ``task_reject_on_worker_lost``).
"""

from __future__ import annotations

import time
import uuid
from pathlib import Path
from typing import Any

import httpx
import pytest
from reliability_helpers import (
    ADMIN_KEY,
    CSV,
    SWARM_A_TLE,
    T0_UTC_S,
    fork_server,
    free_port,
    kill9,
    physical_csv,
    pid_alive,
    require_service,
    sqlite_query,
    sqlite_settings,
    wait_healthy,
)

from service.jobs import run_retrain
from service.settings import Settings
from service.storage import make_engine

H = {"X-API-Key": ADMIN_KEY}


def _wait_job(url: str, job_id: str, until: set[str], timeout_s: float = 120.0) -> dict[str, Any]:
    t0 = time.monotonic()
    while True:
        job = httpx.get(f"{url}/v1/jobs/{job_id}", headers=H, timeout=10).json()
        if job["status"] in until:
            return job  # type: ignore[no-any-return]
        assert time.monotonic() - t0 < timeout_s, f"job {job_id} still {job['status']}"
        time.sleep(0.05)


def _wait_db_status(db: Path, job_id: str, status: str, timeout_s: float = 120.0) -> None:
    t0 = time.monotonic()
    while sqlite_query(db, "SELECT status FROM jobs WHERE id = ?", (job_id,)) != [(status,)]:
        assert time.monotonic() - t0 < timeout_s, f"job {job_id} never became {status}"
        time.sleep(0.05)


def _served(url: str) -> dict[str, Any]:
    r = httpx.get(f"{url}/v1/spacecraft/job-1/calibration", headers=H, timeout=30)
    assert r.status_code == 200, r.text
    return r.json()  # type: ignore[no-any-return]


def _first_calibration(url: str) -> dict[str, Any]:
    r = httpx.post(
        url + "/v1/spacecraft", json={"id": "job-1", "tle": SWARM_A_TLE}, headers=H, timeout=30
    )
    assert r.status_code == 201, r.text
    r = httpx.post(
        url + "/v1/spacecraft/job-1/telemetry",
        content=physical_csv(T0_UTC_S, 600),
        headers={**H, **CSV},
        timeout=60,
    )
    assert r.json()["accepted"] == 600, r.text
    r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=30)
    assert r.status_code == 202
    job = _wait_job(url, r.json()["job_id"], {"succeeded", "failed"})
    assert job["status"] == "succeeded", job
    served = _served(url)
    assert served["version"] == 1
    return served


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_kill_9_of_the_api_mid_retraining_fails_the_job_and_keeps_the_calibration(
    tmp_path: Path,
) -> None:
    db = tmp_path / "jobs.sqlite"
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    spec = {"kind": "app", "port": port, "settings": sqlite_settings(db)}
    with fork_server(tmp_path) as fs:
        pid = fs.spawn(spec)
        wait_healthy(url, pid=pid)
        served_before = _first_calibration(url)
        kill9(pid)

        # A server whose fits take 60 s: start a retraining and kill the process inside it.
        pid = fs.spawn({**spec, "fit_delay_s": 60})
        wait_healthy(url, pid=pid)
        r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=30)
        job_id = r.json()["job_id"]
        _wait_job(url, job_id, {"running"})
        time.sleep(0.3)
        kill9(pid)
        # The crash left the job running and the lock taken (what recovery must undo).
        assert sqlite_query(db, "SELECT status FROM jobs WHERE id = ?", (job_id,)) == [("running",)]
        assert sqlite_query(db, "SELECT job_id FROM retrain_locks") == [(job_id,)]

        pid = fs.spawn(spec)
        wait_healthy(url, pid=pid)
        job = _wait_job(url, job_id, {"succeeded", "failed"}, timeout_s=10)
        assert job["status"] == "failed" and "interrupted" in job["error"], job
        assert sqlite_query(db, "SELECT COUNT(*) FROM retrain_locks") == [(0,)]
        assert _served(url) == served_before  # byte-for-byte the same document, still v1
        versions = httpx.get(f"{url}/v1/spacecraft/job-1/calibrations", headers=H).json()
        assert [v["version"] for v in versions] == [1]
        # The lock is free: the next retraining runs to completion.
        r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=30)
        assert r.json()["job_id"] != job_id
        assert _wait_job(url, r.json()["job_id"], {"succeeded", "failed"})["status"] == "succeeded"
        kill9(pid)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_kill_9_of_a_worker_mid_retraining_then_redelivery_ends_the_job(tmp_path: Path) -> None:
    db = tmp_path / "worker.sqlite"
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    settings = sqlite_settings(db)
    with fork_server(tmp_path) as fs:
        pid = fs.spawn({"kind": "app", "port": port, "settings": settings})
        wait_healthy(url, pid=pid)
        served_before = _first_calibration(url)
        kill9(pid)
        # Queue a job through an API whose broker is down: it stays queued in the database.
        dead_broker = {
            **settings,
            "job_backend": "celery",
            "broker_url": f"redis://127.0.0.1:{free_port()}/0",
        }
        pid = fs.spawn({"kind": "app", "port": port, "settings": dead_broker})
        wait_healthy(url, pid=pid)
        r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=30)
        assert r.status_code == 202, r.text
        job_id = r.json()["job_id"]
        assert _wait_job(url, job_id, {"queued"})["status"] == "queued"
        kill9(pid)
        engine = make_engine(f"sqlite:///{db}")
        # A worker process picks it up and dies inside the fit.
        worker = fs.spawn(
            {"kind": "retrain", "settings": settings, "job_id": job_id, "fit_delay_s": 60}
        )
        _wait_db_status(db, job_id, "running")
        time.sleep(0.3)
        kill9(worker)
        assert not pid_alive(worker)
        assert sqlite_query(db, "SELECT job_id FROM retrain_locks") == [(job_id,)]
        # Celery redelivers the unacknowledged task to another worker: it must end the job.
        status = run_retrain(engine, Settings(**settings), job_id)
        assert status in ("failed", "succeeded"), status
        [(db_status, error)] = sqlite_query(
            db, "SELECT status, error FROM jobs WHERE id = ?", (job_id,)
        )
        assert db_status == status
        assert sqlite_query(db, "SELECT COUNT(*) FROM retrain_locks") == [(0,)]
        if status == "failed":
            assert error and "interrupted" in error
            [(n_versions,)] = sqlite_query(db, "SELECT COUNT(*) FROM calibrations")
            assert n_versions == 1
            pid = fs.spawn({"kind": "app", "port": port, "settings": settings})
            wait_healthy(url, pid=pid)
            assert _served(url) == served_before
            kill9(pid)
        engine.dispose()


@pytest.mark.services
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_kill_9_of_a_celery_worker_mid_retraining_over_rabbitmq(tmp_path: Path) -> None:
    """The real thing: ``orbitcal worker`` (Celery, RabbitMQ) killed inside a fit; RabbitMQ
    redelivers the unacknowledged task to the next worker, which ends the job."""
    require_service("RabbitMQ", 5672)
    from kombu import Connection

    db = tmp_path / "celery.sqlite"
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    broker = "amqp://guest:guest@127.0.0.1:5672//"
    queue = f"orbitcal-reliability-{uuid.uuid4().hex[:8]}"
    settings = sqlite_settings(db)
    celery_settings = {**settings, "job_backend": "celery", "broker_url": broker, "queue": queue}
    worker_env = {"ORBITCAL_QUEUE": queue, "ORBITCAL_LOG_LEVEL": "WARNING"}
    worker_argv = ["worker", "--broker", broker, "--database", f"sqlite:///{db}"]
    try:
        with fork_server(tmp_path) as fs:
            pid = fs.spawn({"kind": "app", "port": port, "settings": settings})
            wait_healthy(url, pid=pid)
            served_before = _first_calibration(url)
            kill9(pid)
            api = fs.spawn({"kind": "app", "port": port, "settings": celery_settings})
            wait_healthy(url, pid=api)
            worker = fs.spawn(
                {"kind": "cli", "argv": worker_argv, "env": worker_env, "patch_fit_delay_s": 60}
            )
            r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=60)
            job_id = r.json()["job_id"]
            _wait_job(url, job_id, {"running"}, timeout_s=120)
            time.sleep(0.3)
            kill9(worker)
            assert sqlite_query(db, "SELECT job_id FROM retrain_locks") == [(job_id,)]
            # A fresh worker gets the redelivered task and ends the job.
            fs.spawn({"kind": "cli", "argv": worker_argv, "env": worker_env})
            job = _wait_job(url, job_id, {"succeeded", "failed"}, timeout_s=120)
            assert job["status"] == "failed" and "interrupted" in job["error"], job
            assert sqlite_query(db, "SELECT COUNT(*) FROM retrain_locks") == [(0,)]
            assert _served(url) == served_before
            # The lock is free: the next retraining runs on the new worker.
            r = httpx.post(url + "/v1/spacecraft/job-1/calibrations", headers=H, timeout=60)
            job = _wait_job(url, r.json()["job_id"], {"succeeded", "failed"}, timeout_s=120)
            assert job["status"] == "succeeded", job
    finally:
        with Connection(broker) as conn:
            conn.default_channel.queue_delete(queue)
