"""Operations: ``orbitcal serve`` as a real process, 503 + Retry-After when the database is
down, recovery of jobs interrupted by a restart, migrations both ways."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import sqlalchemy as sa
from service_helpers import ADMIN_KEY, live_server, sqlite_settings, wait_job
from service_worlds import T0_UTC_S, world

from service.storage import Job, RetrainLock, Spacecraft, make_engine, upgrade, write_tx


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_orbitcal_serve_runs_the_service_and_logs_no_secret(tmp_path: Path) -> None:
    port = _free_port()
    env = {**os.environ, "ORBITCAL_ADMIN_KEY": ADMIN_KEY, "ORBITCAL_SCHEDULER_TICK_S": "1"}
    db = tmp_path / "served.sqlite"
    proc = subprocess.Popen(
        [sys.executable, "-m", "orbitcal", "serve", "--port", str(port), "--database",
         f"sqlite:///{db}"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        with httpx.Client(base_url=url, headers={"X-API-Key": ADMIN_KEY}) as c:
            assert c.post("/v1/spacecraft", json={"id": "proc"}).status_code == 201
            csv = world(T0_UTC_S, 20)[0].to_csv(index=False)
            r = c.post("/v1/spacecraft/proc/telemetry", content=csv,
                       headers={"content-type": "text/csv"})  # fmt: skip
            assert r.json()["accepted"] == 20
            r = c.post("/v1/keys", json={"name": "k", "scopes": ["read:*"]})
            new_key = r.json()["key"]
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=30)
    # uvicorn shuts down gracefully, then re-raises the captured SIGTERM
    assert proc.returncode in (0, -15), err.decode()[-2000:]
    logs = out.decode() + err.decode()
    assert "orbitcal serve: http://127.0.0.1" in logs
    assert ADMIN_KEY not in logs and new_key not in logs
    # a committed upload is in the file after the process is gone
    engine = make_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        assert conn.execute(sa.text("SELECT count(*) FROM samples")).scalar() == 20
    engine.dispose()


def test_no_auth_is_refused_off_loopback(capsys: pytest.CaptureFixture[str]) -> None:
    from orbitcal.cli import main

    assert main(["serve", "--host", "0.0.0.0", "--no-auth"]) == 2
    err = capsys.readouterr().err
    assert "refused" in err and "127.0.0.1" in err


def test_database_down_gives_503_with_retry_after(tmp_path: Path) -> None:
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "s"}).status_code == 201
        good = server.app.state.engine
        # nothing listens on port 1: every connection attempt fails
        server.app.state.engine = make_engine("postgresql://postgres@127.0.0.1:1/none")
        try:
            csv = world(T0_UTC_S, 5)[0].to_csv(index=False)
            r = c.post("/v1/spacecraft/s/telemetry", content=csv,
                       headers={"content-type": "text/csv"})  # fmt: skip
            assert r.status_code == 503 and r.headers["retry-after"] == "5"
            assert "nothing was stored" in r.json()["detail"]
            assert c.get("/v1/spacecraft/s/calibrations").status_code == 503
            assert c.get("/healthz").status_code == 200
        finally:
            server.app.state.engine.dispose()
            server.app.state.engine = good
        assert c.get("/v1/spacecraft/s").json()["samples"] == 0


def test_restart_fails_interrupted_jobs_releases_locks_and_runs_queued_ones(
    tmp_path: Path,
) -> None:
    settings = sqlite_settings(tmp_path)
    engine = make_engine(settings.database_url)
    upgrade(engine)
    with write_tx(engine) as conn:
        conn.execute(
            sa.insert(Spacecraft).values(
                id="s", attitude_frame="GCRS", created_at=0, sample_count=0, samples_at_last_job=0
            )
        )
        now = time.time()
        for job_id, status in (("a" * 32, "running"), ("b" * 32, "queued")):
            conn.execute(
                sa.insert(Job).values(
                    id=job_id, spacecraft_pk=1, kind="retrain", trigger="api", status=status,
                    params={"min_samples": 10}, created_at=now,
                )
            )  # fmt: skip
        conn.execute(
            sa.insert(RetrainLock).values(spacecraft_pk=1, job_id="a" * 32, acquired_at=now)
        )
    engine.dispose()
    with live_server(settings) as server, server.client() as c:
        interrupted = c.get("/v1/jobs/" + "a" * 32).json()
        assert interrupted["status"] == "failed" and "interrupted" in interrupted["error"]
        # the queued job ran (and failed cleanly: this spacecraft has no data), lock released
        queued = wait_job(c, "b" * 32)
        assert queued["status"] == "failed" and "no usable telemetry" in queued["error"]
        with server.app.state.engine.connect() as conn:
            assert conn.execute(sa.select(sa.func.count()).select_from(RetrainLock)).scalar() == 0


def test_migrations_downgrade_and_upgrade(tmp_path: Path) -> None:
    from alembic import command
    from alembic.config import Config

    engine = make_engine(f"sqlite:///{tmp_path / 'm.sqlite'}")
    upgrade(engine)
    cfg = Config(str(Path(__file__).resolve().parents[2] / "service" / "alembic.ini"))
    cfg.set_main_option(
        "script_location", str(Path(__file__).resolve().parents[2] / "service" / "migrations")
    )
    with engine.connect() as conn:
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, "base")
        conn.commit()
        assert "samples" not in sa.inspect(conn).get_table_names()
    upgrade(engine)
    with engine.connect() as conn:
        tables = set(sa.inspect(conn).get_table_names())
        pk = sa.inspect(conn).get_pk_constraint("samples")["constrained_columns"]
    assert {"spacecraft", "samples", "calibrations", "jobs", "retrain_locks", "api_keys"} <= tables
    assert pk == ["spacecraft_pk", "t_utc_us"]
    engine.dispose()


def test_scheduler_fails_jobs_of_a_lost_worker_and_releases_the_lock(tmp_path: Path) -> None:
    from service.jobs import InlineRunner
    from service.scheduler import FleetScheduler

    settings = sqlite_settings(tmp_path, lock_timeout_s=60.0)
    engine = make_engine(settings.database_url)
    upgrade(engine)
    old = time.time() - 120
    with write_tx(engine) as conn:
        conn.execute(
            sa.insert(Spacecraft).values(
                id="s", attitude_frame="GCRS", created_at=0, sample_count=0, samples_at_last_job=0
            )
        )
        conn.execute(
            sa.insert(Job).values(
                id="c" * 32, spacecraft_pk=1, kind="retrain", trigger="api", status="running",
                params={}, created_at=old, started_at=old,
            )
        )  # fmt: skip
        conn.execute(
            sa.insert(RetrainLock).values(spacecraft_pk=1, job_id="c" * 32, acquired_at=old)
        )
    runner = InlineRunner(engine, settings)
    FleetScheduler(engine, settings, runner).tick()
    runner.shutdown()
    with engine.connect() as conn:
        status, error = conn.execute(sa.select(Job.status, Job.error)).one()
        locks = conn.execute(sa.select(sa.func.count()).select_from(RetrainLock)).scalar()
    assert status == "failed" and "worker lost" in str(error) and locks == 0
    engine.dispose()


def test_migrations_match_the_models(tmp_path: Path) -> None:
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    from service.storage import Base

    engine = make_engine(f"sqlite:///{tmp_path / 'cmp.sqlite'}")
    upgrade(engine)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    engine.dispose()
    assert diff == []
