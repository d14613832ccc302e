"""Retraining jobs: creation (one live job per spacecraft), the job function, and its runners.

The job function :func:`run_retrain` is the same for the in-process runner and for Celery workers.
It reads the spacecraft's window (chosen robustly, quarantined rows left out), hands the science to
:func:`orbitcal.pipeline.retrain` (fit the challenger, score challenger and champion on the same
held-out later block, decide the promotion) and in one transaction stores the challenger as a new
immutable version: ``in_service`` (the champion becomes ``superseded``) if promoted, ``rejected``
with the reason otherwise. Any failure leaves the served calibration untouched and is recorded on
the job. A lock row per spacecraft keeps retrainings of one spacecraft serial.
"""

from __future__ import annotations

import logging
import subprocess
import time
import uuid
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import sqlalchemy as sa
from sqlalchemy.engine import Engine

import orbitcal
from orbitcal import pipeline
from orbitcal.pipeline import (
    Champion,
    PromotionRule,
    RetrainOptions,
    RowRules,
    TrainingRows,
    orbit_from,
    retrain,
    training_rows,
)
from orbitcal.timescales import utc_s_to_iso
from service.params import RetrainParams, Schedule
from service.settings import Settings
from service.storage import (
    Calibration,
    Job,
    Spacecraft,
    acquire_lock,
    read_tx,
    read_window,
    release_lock,
    write_tx,
)
from service.threads import DaemonPool

__all__ = [
    "FitFunction",
    "InlineRunner",
    "JobRunner",
    "code_version",
    "create_job",
    "reap_abandoned",
    "recover_interrupted",
    "run_retrain",
]

log = logging.getLogger("orbitcal.service.jobs")

#: ``fit(telemetry, *, orbit, method, field, attitude_frame, holdout_fraction, rng) -> document``
FitFunction = Callable[..., dict[str, Any]]


@cache
def code_version() -> str:
    """``orbitcal <version>`` plus the git commit when running from a checkout."""
    version = f"orbitcal {orbitcal.__version__}"
    root = Path(__file__).resolve().parents[1]
    if (root / ".git").exists():
        try:
            commit = subprocess.run(
                ["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"],
                capture_output=True,
                text=True,
                timeout=5,
                check=True,
            ).stdout.strip()
            version += f" ({commit})"
        except (OSError, subprocess.SubprocessError):
            pass
    return version


def create_job(
    engine: Engine,
    settings: Settings,
    spacecraft_pk: int,
    *,
    trigger: str,
    overrides: dict[str, Any] | None = None,
) -> tuple[str, bool]:
    """Create a retraining job unless one is already queued or running: ``(job_id, created)``.

    The job's parameters (:class:`service.params.RetrainParams`: method, field, window, hold-out
    share, minimum samples, seed) are resolved here, once, from ``overrides``, the spacecraft's
    schedule and the settings, and stored with the job, so that whichever process runs it
    (thread or Celery worker) fits exactly what was asked.
    """
    now = time.time()
    stale_after_s = settings.lock_timeout_s
    with write_tx(engine) as conn:
        stored_schedule = conn.execute(
            sa.select(Spacecraft.schedule).where(Spacecraft.pk == spacecraft_pk)
        ).scalar_one_or_none()
        params = RetrainParams.resolve(
            settings,
            schedule=Schedule.from_stored(stored_schedule, spacecraft=spacecraft_pk),
            overrides=overrides,
        )
        existing = conn.execute(
            sa.select(Job.id)
            .where(
                Job.spacecraft_pk == spacecraft_pk,
                Job.status.in_(("queued", "running")),
                Job.created_at > now - stale_after_s,
            )
            .order_by(Job.created_at.desc())
            .limit(1)
        ).scalar_one_or_none()
        if existing is not None:
            return existing, False
        job_id = uuid.uuid4().hex
        conn.execute(
            sa.insert(Job).values(
                id=job_id,
                spacecraft_pk=spacecraft_pk,
                kind="retrain",
                trigger=trigger,
                status="queued",
                params=params.stored(),
                created_at=now,
            )
        )
        conn.execute(
            sa.update(Spacecraft)
            .where(Spacecraft.pk == spacecraft_pk)
            .values(samples_at_last_job=Spacecraft.sample_count, last_job_at=now)
        )
    return job_id, True


def _read_inputs(
    engine: Engine, settings: Settings, params: RetrainParams, sc: Any
) -> tuple[Any, TrainingRows, Any, Any]:
    """One read transaction: the robust window, its rows to fit (``pipeline.training_rows``)
    and the champion."""
    with read_tx(engine) as conn:
        window, samples = read_window(
            conn,
            sc.pk,
            window_s=params.window_s,
            min_samples=params.min_samples,
            now_utc_s=time.time(),
        )
        champion = conn.execute(
            sa.select(Calibration.version, Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).first()
        window, samples = _after_change(conn, sc.pk, window, samples)
    rows = training_rows(
        window,
        samples.t_utc_s,
        has_attitude=samples.has("q_w", "q_x", "q_y", "q_z"),
        has_position=samples.has("r_x", "r_y", "r_z"),
        rules=RowRules(
            method=params.method,
            have_orbit=bool(sc.tle or sc.omm),
            min_samples=params.min_samples,
            quiet_kp_max=settings.quiet_kp_max,
            quiet_dst_min_nt=settings.quiet_dst_min_nt,
        ),
        spacecraft=sc.id,
    )
    return samples.select(rows.mask).to_telemetry(), rows, window, champion


def _after_change(conn: Any, spacecraft_pk: int, window: Any, samples: Any) -> tuple[Any, Any]:
    """The window cut at the latest change the health check found (service.health): a
    retraining never mixes data from before a sensor change with data after it."""
    from orbitcal.pipeline import Window
    from service.health import change_since_utc_s

    since = change_since_utc_s(conn, spacecraft_pk)
    if since is None or window.start_utc_s is None or window.start_utc_s >= since:
        return window, samples
    keep = samples.t_utc_s >= since
    n_before = int(np.count_nonzero(~keep))
    if not n_before:
        return window, samples
    excluded = {**window.excluded, "before_change": n_before}
    if not keep.any():
        return Window(None, None, 0, excluded), samples.select(keep)
    return Window(since, window.end_utc_s, int(np.count_nonzero(keep)), excluded), samples.select(
        keep
    )


def _retrain(
    engine: Engine, settings: Settings, job: Any, sc: Any, fit: FitFunction
) -> dict[str, Any]:
    params = RetrainParams.from_stored(dict(job.params), settings)
    telemetry, selection, window, champion = _read_inputs(engine, settings, params, sc)
    outcome = retrain(
        telemetry,
        orbit=orbit_from(sc.tle, sc.omm),
        champion=None if champion is None else Champion(champion.document, champion.version),
        options=RetrainOptions(
            method=params.method,
            field=params.field,
            attitude_frame=sc.attitude_frame,
            holdout_fraction=params.holdout_fraction,
            rule=PromotionRule(margin=settings.promote_margin, alpha=settings.promote_alpha),
        ),
        rng=np.random.default_rng(params.seed),
        fit=fit,
    )
    document, decision = outcome.document, outcome.promotion
    rows = selection.summary(extra=outcome.excluded)
    provenance = {
        "job_id": job.id,
        "trigger": job.trigger,
        "code_version": code_version(),
        "orbit": "tle" if sc.tle else ("omm" if sc.omm else "telemetry positions"),
        "window_s": params.window_s,
        "window": {
            "start": utc_s_to_iso([float(window.start_utc_s)])[0],
            "end": utc_s_to_iso([float(window.end_utc_s)])[0],
        },
        **outcome.provenance(rows=rows),
    }
    now = time.time()
    with write_tx(engine) as conn:
        version = (
            conn.execute(
                sa.select(sa.func.max(Calibration.version)).where(
                    Calibration.spacecraft_pk == sc.pk
                )
            ).scalar_one_or_none()
            or 0
        ) + 1
        document = {
            **document,
            "spacecraft": sc.id,
            "version": version,
            "created_at": document.get("created_at") or utc_s_to_iso([now])[0],
        }
        if decision.promote:
            conn.execute(
                sa.update(Calibration)
                .where(Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service")
                .values(status="superseded", reason=f"superseded by version {version}")
            )
        conn.execute(
            sa.insert(Calibration).values(
                spacecraft_pk=sc.pk,
                version=version,
                status="in_service" if decision.promote else "rejected",
                reason=decision.reason,
                created_at=now,
                job_id=job.id,
                holdout_rms_nt=decision.challenger_rms_nt,
                document=document,
                provenance=provenance,
            )
        )
    from service.health import is_stale, record_holdout
    from service.yamcs_hook import push_after_promotion  # issue 21

    pushed = None
    if decision.promote:
        record_holdout(
            engine,
            settings,
            sc.pk,
            version=version,
            start_utc_s=outcome.holdout_start_utc_s,
            end_utc_s=outcome.holdout_end_utc_s,
        )
        with read_tx(engine) as conn:
            stale = is_stale(conn, sc.pk, version)
        pushed = push_after_promotion(settings, document, stale=stale)
    return {
        "yamcs_push": pushed,
        "version": version,
        "promoted": decision.promote,
        "reason": decision.reason,
        "rule": decision.rule,
        "method": provenance["method"],
        "metric": decision.metric,
        "holdout_rms_nt": decision.challenger_rms_nt,
        "champion_rms_nt": decision.champion_rms_nt,
        "identity_rms_nt": decision.identity_rms_nt,
        "p_value": decision.p_value,
        "rows": rows,
    }


def run_retrain(
    engine: Engine,
    settings: Settings,
    job_id: str,
    *,
    fit: FitFunction | None = None,
    on_done: Callable[[str, float], None] | None = None,
) -> str:
    """Run one retraining job to completion; return its final status. Idempotent on redelivery."""
    fit = fit or pipeline.fit_document  # looked up per call: tests may patch it
    with write_tx(engine) as conn:
        job = conn.execute(sa.select(Job).where(Job.id == job_id)).first()
        if job is None:
            log.warning("job not found", extra={"job_id": job_id})
            return "missing"
        if job.status == "running":
            # Delivered again while marked running: the process running it died (Celery
            # redelivers an unacknowledged task only after a worker loss or the visibility
            # timeout). End it and free the lock; the served calibration was never touched.
            conn.execute(
                sa.update(Job)
                .where(Job.id == job_id)
                .values(
                    status="failed",
                    error="interrupted: the worker running this job was lost (redelivered)",
                    finished_at=time.time(),
                )
            )
            release_lock(conn, job.spacecraft_pk, job_id)
            return "failed"
        if job.status != "queued":
            return str(job.status)
        if not acquire_lock(conn, job.spacecraft_pk, job_id, timeout_s=settings.lock_timeout_s):
            conn.execute(
                sa.update(Job)
                .where(Job.id == job_id)
                .values(
                    status="failed",
                    error="another retraining of this spacecraft is running",
                    finished_at=time.time(),
                )
            )
            return "failed"
        started = time.time()
        conn.execute(
            sa.update(Job).where(Job.id == job_id).values(status="running", started_at=started)
        )
        sc = conn.execute(sa.select(Spacecraft).where(Spacecraft.pk == job.spacecraft_pk)).one()
    t0 = time.perf_counter()
    status, error, result = "failed", None, None
    try:
        result = _retrain(engine, settings, job, sc, fit)
        status = "succeeded"
    except Exception as exc:  # a failed job is recorded, never raised into the runner
        error = f"{type(exc).__name__}: {exc}"
        log.warning(
            "retraining failed", extra={"job_id": job_id, "spacecraft": sc.id, "error": error}
        )
    finally:
        with write_tx(engine) as conn:
            conn.execute(
                sa.update(Job)
                .where(Job.id == job_id)
                .values(status=status, error=error, result=result, finished_at=time.time())
            )
            release_lock(conn, job.spacecraft_pk, job_id)
    elapsed = time.perf_counter() - t0
    log.info(
        "retraining finished",
        extra={"job_id": job_id, "spacecraft": sc.id, "status": status, "seconds": elapsed},
    )
    if on_done is not None:
        on_done(status, elapsed)
    return status


def reap_abandoned(engine: Engine, *, timeout_s: float) -> list[str]:
    """Fail ``running`` jobs whose lock is older than ``timeout_s`` (their worker died) and
    release those locks. Returns the ids of the jobs failed."""
    from service.storage import RetrainLock

    cutoff = time.time() - timeout_s
    with write_tx(engine) as conn:
        stale = (
            conn.execute(
                sa.select(Job.id)
                .join(RetrainLock, RetrainLock.job_id == Job.id)
                .where(Job.status == "running", RetrainLock.acquired_at < cutoff)
            )
            .scalars()
            .all()
        )
        orphans = (
            conn.execute(
                sa.select(Job.id).where(
                    Job.status == "running",
                    Job.started_at < cutoff,
                    ~sa.exists().where(RetrainLock.job_id == Job.id),
                )
            )
            .scalars()
            .all()
        )
        ids = [*stale, *orphans]
        if ids:
            conn.execute(
                sa.update(Job)
                .where(Job.id.in_(ids))
                .values(
                    status="failed",
                    error=f"abandoned: no progress for {timeout_s:g} s (worker lost)",
                    finished_at=time.time(),
                )
            )
            conn.execute(sa.delete(RetrainLock).where(RetrainLock.job_id.in_(ids)))
    if ids:
        log.warning("abandoned jobs failed", extra={"jobs": ids})
    return list(ids)


def recover_interrupted(engine: Engine) -> list[str]:
    """After a restart of the only process running inline jobs: fail its ``running`` jobs.

    Returns the ids of jobs still ``queued`` (to resubmit). Locks of failed jobs are released.
    """
    from service.storage import RetrainLock

    with write_tx(engine) as conn:
        running = conn.execute(sa.select(Job.id).where(Job.status == "running")).scalars().all()
        if running:
            conn.execute(
                sa.update(Job)
                .where(Job.id.in_(running))
                .values(
                    status="failed",
                    error="interrupted: the service stopped while the job ran",
                    finished_at=time.time(),
                )
            )
            conn.execute(sa.delete(RetrainLock).where(RetrainLock.job_id.in_(running)))
        queued = (
            conn.execute(sa.select(Job.id).where(Job.status == "queued").order_by(Job.created_at))
            .scalars()
            .all()
        )
    return list(queued)


class JobRunner(Protocol):
    def submit(self, job_id: str) -> None: ...

    def shutdown(self) -> None: ...


class InlineRunner:
    """Runs jobs in a small thread pool inside the API process (the embedded default)."""

    def __init__(
        self,
        engine: Engine,
        settings: Settings,
        *,
        fit: FitFunction | None = None,
        on_done: Callable[[str, float], None] | None = None,
    ) -> None:
        self.engine = engine
        self.settings = settings
        self.fit = fit
        self.on_done = on_done
        self.pool = DaemonPool(settings.inline_workers, "orbitcal-job")

    def submit(self, job_id: str) -> None:
        self.pool.submit(
            run_retrain, self.engine, self.settings, job_id, fit=self.fit, on_done=self.on_done
        )

    def shutdown(self, timeout_s: float | None = None) -> None:
        """Let the jobs submitted run for at most ``timeout_s`` (default
        ``settings.shutdown_timeout_s``); then a job not started is cancelled (still ``queued``
        in the database: resubmitted at the next start) and a running one is left behind (failed
        as interrupted at the next start)."""
        wait_s = self.settings.shutdown_timeout_s if timeout_s is None else timeout_s
        if not self.pool.shutdown(timeout_s=wait_s, cancel_pending=False):
            log.warning(
                "a retraining still running at shutdown is left behind",
                extra={"waited_s": wait_s},
            )
