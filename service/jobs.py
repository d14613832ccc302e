"""Retraining jobs: creation (one live job per spacecraft), the job function, and its runners.

The job function :func:`run_retrain` is the same for the in-process runner and for Celery workers.
It fits a challenger on the spacecraft's sliding window, scores challenger and champion (the
calibration in service) on the same held-out later block, and in one transaction stores the
challenger as a new immutable version: ``in_service`` (the champion becomes ``superseded``) if it is
better, ``rejected`` with the reason otherwise. Any failure leaves the served calibration untouched
and is recorded on the job. A lock row per spacecraft keeps retrainings of one spacecraft serial.
"""

from __future__ import annotations

import logging
import subprocess
import time
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import sqlalchemy as sa
from sqlalchemy.engine import Engine

import orbitcal
from orbitcal.calibrate.holdout import later_block_split
from orbitcal.telemetry import Telemetry
from orbitcal.timescales import utc_s_to_iso
from service import science
from service.settings import Settings
from service.storage import (
    Calibration,
    Job,
    SampleArrays,
    Spacecraft,
    acquire_lock,
    read_samples,
    read_tx,
    release_lock,
    write_tx,
)

__all__ = [
    "FitFunction",
    "InlineRunner",
    "JobRunner",
    "code_version",
    "create_job",
    "reap_abandoned",
    "recover_interrupted",
    "run_retrain",
    "samples_to_telemetry",
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

    The job's parameters (method, field, window, hold-out share, seed) are resolved here, from
    ``overrides``, the spacecraft's schedule and the settings, and stored with the job, so that
    whichever process runs it (thread or Celery worker) fits exactly what was asked.
    """
    now = time.time()
    stale_after_s = settings.lock_timeout_s
    with write_tx(engine) as conn:
        schedule = (
            conn.execute(
                sa.select(Spacecraft.schedule).where(Spacecraft.pk == spacecraft_pk)
            ).scalar_one_or_none()
            or {}
        )
        params: dict[str, Any] = {
            "method": settings.method,
            "field": settings.reference_field,
            "window_s": float(schedule.get("window_s") or settings.window_s),
            "holdout_fraction": settings.holdout_fraction,
            "min_samples": settings.min_samples,
            "seed": 0,
            **(overrides or {}),
        }
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
                params=params,
                created_at=now,
            )
        )
        conn.execute(
            sa.update(Spacecraft)
            .where(Spacecraft.pk == spacecraft_pk)
            .values(samples_at_last_job=Spacecraft.sample_count, last_job_at=now)
        )
    return job_id, True


def samples_to_telemetry(s: SampleArrays) -> Telemetry:
    """Stored columns → ``Telemetry`` (an optional group is kept when every row has it)."""

    def group(*names: str) -> np.ndarray | None:
        block = np.stack([s.columns[c] for c in names], axis=-1)
        return None if np.isnan(block).any() else block

    q = group("q_w", "q_x", "q_y", "q_z")
    r = group("r_x", "r_y", "r_z")
    temp = group("temperature")
    mtq = group("mtq_x", "mtq_y", "mtq_z")
    hk = {k: v for k, v in s.hk.items() if not np.isnan(v).any()}
    return Telemetry(
        t_utc_s=s.t_utc_s,
        b_raw_nt=group("b_x", "b_y", "b_z") if len(s) else np.zeros((0, 3)),  # type: ignore[arg-type]
        q_wxyz=q,
        r_itrs_km=r,
        temperature_c=None if temp is None else temp[:, 0],
        mtq_am2=mtq,
        hk=hk,
    )


def _subset(tel: Telemetry, sl: slice) -> Telemetry:
    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[sl]

    return Telemetry(
        t_utc_s=tel.t_utc_s[sl],
        b_raw_nt=tel.b_raw_nt[sl],
        q_wxyz=cut(tel.q_wxyz),
        r_itrs_km=cut(tel.r_itrs_km),
        temperature_c=cut(tel.temperature_c),
        mtq_am2=cut(tel.mtq_am2),
        hk={k: v[sl] for k, v in tel.hk.items()},
    )


def _rms(b_cal: np.ndarray, b_ref: np.ndarray) -> float:
    """RMS over samples and the three components of ``b_cal - b_ref`` [nT]."""
    return float(np.sqrt(np.mean((b_cal - b_ref) ** 2)))


def _retrain(
    engine: Engine, settings: Settings, job: Any, sc: Any, fit: FitFunction
) -> dict[str, Any]:
    params = dict(job.params)
    window_s = float(params.get("window_s") or settings.window_s)
    method = str(params.get("method") or settings.method)
    field = str(params.get("field") or settings.reference_field)
    holdout_fraction = float(params.get("holdout_fraction", settings.holdout_fraction))
    min_samples = int(params.get("min_samples", settings.min_samples))
    with read_tx(engine) as conn:
        latest_us = conn.execute(
            sa.text("SELECT MAX(t_utc_us) FROM samples WHERE spacecraft_pk = :pk"),
            {"pk": sc.pk},
        ).scalar_one_or_none()
        if latest_us is None:
            raise ValueError(f"spacecraft {sc.id} has no telemetry yet")
        latest_s = latest_us / 1e6
        samples = read_samples(conn, sc.pk, start_utc_s=latest_s - window_s)
        champion = conn.execute(
            sa.select(Calibration.version, Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).first()
    n = len(samples)
    if n < min_samples:
        raise ValueError(
            f"only {n} samples in the {window_s:g} s window ending {utc_s_to_iso([latest_s])[0]}; "
            f"a retraining needs at least {min_samples}"
        )
    telemetry = samples_to_telemetry(samples)
    orbit = science.load_orbit(sc.tle, sc.omm)
    rng = np.random.default_rng(int(params.get("seed", 0)))
    document = fit(
        telemetry,
        orbit=orbit,
        method=method,
        field=field,
        attitude_frame=sc.attitude_frame,
        holdout_fraction=holdout_fraction,
        rng=rng,
    )
    # Score challenger and champion on the same later block that the fit did not see.
    # (the same later-block split as the pipeline's; telemetry is time-ordered)
    _train, hold_mask = later_block_split(telemetry.t_utc_s, holdout_fraction)
    n_hold = int(np.count_nonzero(hold_mask))
    if n_hold == 0:
        raise ValueError("holdout_fraction leaves no held-out samples to compare calibrations on")
    holdout = _subset(telemetry, slice(n - n_hold, n))
    b_ref = science.reference_body_nt(
        holdout, orbit=orbit, attitude_frame=sc.attitude_frame, field=field
    )
    challenger_rms = _rms(science.apply_document(document, holdout), b_ref)
    champion_rms = (
        None
        if champion is None
        else _rms(science.apply_document(champion.document, holdout), b_ref)
    )
    span = utc_s_to_iso([float(holdout.t_utc_s[0]), float(holdout.t_utc_s[-1])])
    if champion_rms is None:
        promote, reason = True, "first calibration of this spacecraft"
    elif champion is not None and challenger_rms < champion_rms * (1.0 - settings.promote_margin):
        promote = True
        reason = (
            f"held-out RMS {challenger_rms:.3f} nT beats version {champion.version}'s "
            f"{champion_rms:.3f} nT on {span[0]}..{span[1]}"
        )
    else:
        assert champion is not None
        promote = False
        reason = (
            f"held-out RMS {challenger_rms:.3f} nT does not beat version {champion.version}'s "
            f"{champion_rms:.3f} nT in service on {span[0]}..{span[1]}"
        )
    provenance = {
        "job_id": job.id,
        "trigger": job.trigger,
        "code_version": code_version(),
        "method": document.get("method", method),
        "reference_field": document.get("reference_field", field),
        "attitude_frame": sc.attitude_frame,
        "orbit": "tle" if sc.tle else ("omm" if sc.omm else "telemetry positions"),
        "window_s": window_s,
        "data": {
            "start": utc_s_to_iso([float(telemetry.t_utc_s[0])])[0],
            "end": utc_s_to_iso([float(telemetry.t_utc_s[-1])])[0],
            "n": n,
        },
        "comparison": {
            "holdout_start": span[0],
            "holdout_end": span[1],
            "holdout_n": n_hold,
            "challenger_rms_nt": challenger_rms,
            "champion_version": None if champion is None else champion.version,
            "champion_rms_nt": champion_rms,
            "promoted": promote,
        },
        "metrics": document.get("metrics", {}),
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
        if promote:
            conn.execute(
                sa.update(Calibration)
                .where(Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service")
                .values(status="superseded", reason=f"superseded by version {version}")
            )
        conn.execute(
            sa.insert(Calibration).values(
                spacecraft_pk=sc.pk,
                version=version,
                status="in_service" if promote else "rejected",
                reason=reason,
                created_at=now,
                job_id=job.id,
                holdout_rms_nt=challenger_rms,
                document=document,
                provenance=provenance,
            )
        )
    return {
        "version": version,
        "promoted": promote,
        "reason": reason,
        "holdout_rms_nt": challenger_rms,
        "champion_rms_nt": champion_rms,
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
    fit = fit or science.fit_calibration
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
        self.pool = ThreadPoolExecutor(
            max_workers=max(1, settings.inline_workers), thread_name_prefix="orbitcal-job"
        )

    def submit(self, job_id: str) -> None:
        self.pool.submit(
            run_retrain, self.engine, self.settings, job_id, fit=self.fit, on_done=self.on_done
        )

    def shutdown(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)
