"""Celery scale-out: the same job function, run by ``orbitcal worker`` processes.

Workers read their settings (``ORBITCAL_DATABASE_URL`` — PostgreSQL — and ``ORBITCAL_BROKER_URL`` —
``redis://`` or ``amqp://``) from the environment. Tasks are acknowledged late and rejected when a
worker dies, so a killed worker's job is redelivered; :func:`service.jobs.run_retrain` runs a job
only from ``queued``, so redelivery never retrains twice.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import cache

from celery import Celery
from sqlalchemy.engine import Engine

from service.jobs import run_retrain
from service.settings import Settings
from service.storage import make_engine

__all__ = ["TASK_NAME", "CeleryRunner", "make_celery"]

TASK_NAME = "orbitcal.retrain"


@cache
def _worker_engine(url: str) -> Engine:
    return make_engine(url)


def make_celery(settings: Settings) -> Celery:
    app = Celery("orbitcal", broker=settings.broker_url)
    app.conf.update(
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,
        task_ignore_result=True,
        task_default_queue=settings.queue,
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        broker_transport_options={"visibility_timeout": int(settings.lock_timeout_s)},
    )

    @app.task(name=TASK_NAME)  # type: ignore[untyped-decorator]
    def retrain(job_id: str) -> str:
        return run_retrain(_worker_engine(settings.database_url), settings, job_id)

    return app


class CeleryRunner:
    """Sends jobs to the broker. If the broker is down the job stays ``queued`` in the database
    and the scheduler re-submits it later."""

    def __init__(self, settings: Settings) -> None:
        self.app = make_celery(settings)
        self.queue = settings.queue
        # One sender thread, so that no request waits for the broker: with the broker down the
        # Redis client alone retries for ~6 s (found by tests/reliability/test_broker_outage.py).
        self._sender = ThreadPoolExecutor(max_workers=1, thread_name_prefix="orbitcal-send")

    def submit(self, job_id: str) -> None:
        self._sender.submit(self._send, job_id)

    def _send(self, job_id: str) -> None:
        try:
            self.app.send_task(TASK_NAME, args=[job_id], queue=self.queue, retry=False)
        except Exception:  # broker unavailable: the job is durable in the database
            import logging

            logging.getLogger("orbitcal.service.jobs").warning(
                "broker unavailable; job stays queued", extra={"job_id": job_id}
            )

    def shutdown(self) -> None:
        # Unsent jobs stay queued in the database; the scheduler re-submits them.
        self._sender.shutdown(wait=True, cancel_futures=True)
