"""The fleet scheduler (APScheduler 3, one per deployment): decides which spacecraft to retrain.

Every ``scheduler_tick_s`` it creates a retraining job for each spacecraft whose cadence has elapsed
since its last job and that has received at least ``min_new_samples`` since then (per-spacecraft
overrides in ``spacecraft.schedule``), fails jobs whose worker died (lock older than
``lock_timeout_s``, lock released), and re-submits jobs left queued (e.g. while the broker was
down; running a job twice is harmless, :func:`service.jobs.run_retrain` is idempotent).
"""

from __future__ import annotations

import logging
import time

import sqlalchemy as sa
from apscheduler.schedulers.background import BackgroundScheduler
from sqlalchemy.engine import Engine

from service.jobs import JobRunner, create_job, reap_abandoned
from service.params import Schedule
from service.settings import Settings
from service.storage import Job, Spacecraft, read_tx

__all__ = ["FleetScheduler", "due_spacecraft"]

log = logging.getLogger("orbitcal.service.scheduler")

#: A job still queued this long after creation is sent again, then at most this often [s].
RESUBMIT_S = 300.0


def due_spacecraft(engine: Engine, settings: Settings, *, now: float) -> list[int]:
    """Primary keys of spacecraft due for a scheduled retraining at ``now``."""
    with read_tx(engine) as conn:
        rows = conn.execute(
            sa.select(
                Spacecraft.pk,
                Spacecraft.sample_count,
                Spacecraft.samples_at_last_job,
                Spacecraft.last_job_at,
                Spacecraft.schedule,
            )
        ).all()
    due = []
    for pk, count, at_last, last_at, schedule in rows:
        plan = Schedule.from_stored(schedule, spacecraft=pk)
        cadence = settings.cadence_s if plan.cadence_s is None else plan.cadence_s
        min_new = settings.min_new_samples if plan.min_new_samples is None else plan.min_new_samples
        if count - at_last < min_new:
            continue
        if last_at is not None and now - last_at < cadence:
            continue
        due.append(pk)
    return due


class FleetScheduler:
    def __init__(self, engine: Engine, settings: Settings, runner: JobRunner) -> None:
        self.engine = engine
        self.settings = settings
        self.runner = runner
        self._scheduler = BackgroundScheduler(timezone="UTC")
        self._resent: dict[str, float] = {}

    def tick(self) -> list[str]:
        """One scheduling pass; returns the ids of the jobs submitted."""
        now = time.time()
        submitted: list[str] = []
        try:
            reap_abandoned(self.engine, timeout_s=self.settings.lock_timeout_s)
            for pk in due_spacecraft(self.engine, self.settings, now=now):
                job_id, created = create_job(self.engine, self.settings, pk, trigger="schedule")
                if created:
                    self.runner.submit(job_id)
                    submitted.append(job_id)
            with read_tx(self.engine) as conn:
                stuck = (
                    conn.execute(
                        sa.select(Job.id).where(
                            Job.status == "queued",
                            Job.created_at < now - RESUBMIT_S,
                        )
                    )
                    .scalars()
                    .all()
                )
            # re-send each stuck job at most every RESUBMIT_S (a backlog is not a lost message)
            for job_id in stuck:
                if now - self._resent.get(job_id, -1e18) < RESUBMIT_S:
                    continue
                self._resent[job_id] = now
                self.runner.submit(job_id)
                submitted.append(job_id)
            if len(self._resent) > 100_000:
                self._resent.clear()
        except sa.exc.SQLAlchemyError:
            log.warning("scheduler tick skipped: database unavailable", exc_info=True)
        except Exception:
            log.exception("scheduler tick failed")
        if submitted:
            log.info("scheduled retraining", extra={"jobs": submitted})
        return submitted

    def update_tables(self) -> list[dict[str, object]]:
        """Fetch and install the auxiliary tables (leap seconds, EOP, RC index, Kp, Dst).

        A failed or malformed download keeps the installed table (orbitcal.auxdata.update); the
        outcome per table is logged, never raised.
        """
        from orbitcal.auxdata import update

        try:
            results = update()
        except Exception:
            log.exception("auxiliary table update failed")
            return []
        for r in results:
            level = logging.WARNING if r["status"] == "failed" else logging.INFO
            log.log(level, "auxiliary table %s: %s (%s)", r["kind"], r["status"], r.get("reason"))
        return results

    def start(self) -> None:
        self._scheduler.add_job(
            self.tick,
            "interval",
            seconds=self.settings.scheduler_tick_s,
            id="orbitcal-fleet-tick",
            max_instances=1,
            coalesce=True,
        )
        if self.settings.aux_update_s > 0:  # off by default (issue 12): sites opt in
            self._scheduler.add_job(
                self.update_tables,
                "interval",
                seconds=self.settings.aux_update_s,
                id="orbitcal-aux-update",
                max_instances=1,
                coalesce=True,
            )
        self._scheduler.start()

    def shutdown(self) -> None:
        if self._scheduler.running:
            self._scheduler.shutdown(wait=False)
