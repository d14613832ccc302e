"""``orbitcal worker``: a Celery worker running retraining jobs (scale-out), or the fleet scheduler.

``orbitcal worker [--concurrency N] [--broker URL] [--database URL]`` consumes retraining jobs;
``orbitcal worker --scheduler`` runs the one fleet scheduler of a deployment (no HTTP), sending due
jobs to the broker. Both read the ``ORBITCAL_*`` environment for everything else.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Any

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "worker",
        help="run a Celery worker for retraining jobs (or --scheduler: the fleet scheduler)",
        description="Celery worker for orbitcal retraining jobs against PostgreSQL.",
    )
    p.add_argument("--broker", metavar="URL", help="redis://host:6379/0 or amqp://user:pw@host//")
    p.add_argument("--database", metavar="URL", help="postgresql://user@host/db")
    p.add_argument("--concurrency", type=int, default=1, help="worker processes (default 1)")
    p.add_argument(
        "--scheduler",
        action="store_true",
        help="run the fleet scheduler instead of a worker (exactly one per deployment)",
    )
    p.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> Any:
    from service.settings import Settings

    overrides: dict[str, Any] = {"job_backend": "celery"}
    if args.broker:
        overrides["broker_url"] = args.broker
    if args.database:
        overrides["database_url"] = args.database
    return Settings(**overrides)


def run(args: argparse.Namespace) -> int:
    from service.logs import configure_logging, redact_url

    settings = _settings(args)
    configure_logging(settings.log_level)
    if args.scheduler:
        from service.celery_app import CeleryRunner
        from service.scheduler import FleetScheduler
        from service.storage import make_engine, upgrade

        engine = make_engine(settings.database_url)
        upgrade(engine)
        scheduler = FleetScheduler(engine, settings, CeleryRunner(settings))
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        print(
            f"orbitcal worker --scheduler: database {redact_url(settings.database_url)}, "
            f"broker {redact_url(settings.broker_url)}, tick {settings.scheduler_tick_s:g} s",
            file=sys.stderr,
        )
        while not stop.is_set():
            scheduler.tick()
            stop.wait(settings.scheduler_tick_s)
        return 0
    from service.celery_app import make_celery
    from service.storage import make_engine, upgrade

    upgrade(make_engine(settings.database_url))
    app = make_celery(settings)
    app.worker_main(
        [
            "worker",
            f"--concurrency={max(1, args.concurrency)}",
            "--loglevel=INFO",
            "--without-gossip",
            "--without-mingle",
            f"--queues={settings.queue}",
            "--pool=prefork" if args.concurrency > 1 else "--pool=solo",
        ]
    )
    return 0
