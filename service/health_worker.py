"""The thread that scores uploads (``service.health``) and queues the retraining of a stale
calibration: one per app, started by the lifespan."""

from __future__ import annotations

import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

from sqlalchemy.engine import Engine

from service.health import change_since_utc_s, score_new_samples
from service.jobs import create_job
from service.settings import Settings
from service.storage import count_samples, read_tx

__all__ = ["HealthWorker", "request_retraining"]

log = logging.getLogger("orbitcal.service.health")


def request_retraining(engine: Engine, settings: Settings, spacecraft_pk: int) -> str | None:
    """Queue a retraining of a stale spacecraft once ``min_samples`` samples after the change are
    stored; the id of the job created (None: not yet, or one is already live)."""
    with read_tx(engine) as conn:
        since = change_since_utc_s(conn, spacecraft_pk)
        if since is None:
            return None
        n_after = count_samples(conn, spacecraft_pk, start_utc_s=since, include_quarantined=False)
    if n_after < settings.min_samples:
        return None
    job_id, created = create_job(engine, settings, spacecraft_pk, trigger="health")
    return job_id if created else None


class HealthWorker:
    """Scores uploads in one background thread, per spacecraft in order, coalescing uploads that
    arrive while a scoring of that spacecraft waits (it reads every new sample anyway).

    ``submit(pk)`` after an upload's commit; ``wait(pk)`` before answering what the health of
    ``pk`` is. A stale calibration's retraining is queued on ``runner``.
    """

    def __init__(self, engine: Engine, settings: Settings, runner: Any) -> None:
        self.engine = engine
        self.settings = settings
        self.runner = runner
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="orbitcal-health")
        self._guard = threading.Lock()
        self._waiting: dict[int, Any] = {}  # pk -> the upload's rows in memory, or None
        self._last: dict[int, Any] = {}

    def submit(self, spacecraft_pk: int, fresh: Any = None) -> None:
        """Score after an upload; ``fresh``: its telemetry when every row of it was new."""
        with self._guard:
            if spacecraft_pk in self._waiting:
                # a scoring not yet started reads this upload's samples too, from the database
                self._waiting[spacecraft_pk] = None
                return
            self._waiting[spacecraft_pk] = fresh
            self._last[spacecraft_pk] = self._pool.submit(self._run, spacecraft_pk)

    def wait(self, spacecraft_pk: int, timeout_s: float = 60.0) -> None:
        """Until the scoring of ``spacecraft_pk`` submitted so far is done (bounded)."""
        with self._guard:
            future = self._last.get(spacecraft_pk)
        if future is not None:
            try:
                future.result(timeout=timeout_s)
            except FutureTimeout:
                log.warning("health: scoring still running", extra={"pk": spacecraft_pk})

    def _run(self, spacecraft_pk: int) -> None:
        with self._guard:
            fresh = self._waiting.pop(spacecraft_pk, None)
        try:
            if score_new_samples(self.engine, self.settings, spacecraft_pk, fresh=fresh):
                job_id = request_retraining(self.engine, self.settings, spacecraft_pk)
                if job_id is not None:
                    self.runner.submit(job_id)
        except Exception:  # the upload is stored; the next one scores its samples too
            log.exception("health check after upload failed")

    def shutdown(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
