"""``orbitcal serve [--host H] [--port P] [--database URL]``: the HTTP service (CONTRACT section 3).

Settings not given as options come from the ``ORBITCAL_*`` environment (``docs/service.md``).
The database defaults to the SQLite file ``orbitcal.sqlite`` in the current directory.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "serve",
        help="run the HTTP service (ingest, retraining, calibrations)",
        description=(
            "Run the orbitcal HTTP service with uvicorn (one process by default, --workers N for "
            "more; the scheduler runs in one of them). Settings "
            "not given as options come from ORBITCAL_* environment variables (docs/service.md). "
            "ORBITCAL_ADMIN_KEY sets the admin API key: send it as the X-API-Key header to create "
            "the other keys (POST /v1/keys); without it no key can be created (unless --no-auth)."
        ),
        epilog="environment: ORBITCAL_ADMIN_KEY (admin API key), ORBITCAL_DATABASE_URL, "
        "ORBITCAL_BROKER_URL, ORBITCAL_JOB_BACKEND, ... (docs/service.md)",
    )
    p.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument(
        "--database",
        metavar="URL",
        help="SQLAlchemy URL: sqlite:///path.sqlite (default ./orbitcal.sqlite) or "
        "postgresql://user@host/db",
    )
    p.add_argument(
        "--no-auth",
        action="store_true",
        help="no API keys (refused unless --host is a loopback address)",
    )
    p.add_argument(
        "--no-scheduler",
        action="store_true",
        help="do not run the fleet scheduler here (run exactly one per deployment)",
    )
    p.add_argument(
        "--job-backend",
        choices=("inline", "celery"),
        help="run retraining jobs in this process (inline) or on Celery workers",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="API processes (default 1, or ORBITCAL_WORKERS); with N > 1 the rate limiter needs "
        "ORBITCAL_RATE_LIMIT_REDIS_URL (shared buckets) or ORBITCAL_RATE_LIMIT_PER_S=0, and one "
        "process per database runs the scheduler",
    )
    p.add_argument(
        "--forwarded-allow-ips",
        metavar="IPS",
        default=None,
        help="proxies whose X-Forwarded-For names the client (comma-separated addresses or "
        "networks, '*' for any; default ORBITCAL_FORWARDED_ALLOW_IPS, empty: none)",
    )
    p.set_defaults(func=run)


def settings_from_args(args: argparse.Namespace) -> Any:
    from service.settings import Settings

    overrides: dict[str, Any] = {"bind_host": args.host}
    if args.database:
        overrides["database_url"] = args.database
    if args.no_auth:
        overrides["auth"] = False
    if args.no_scheduler:
        overrides["scheduler"] = False
    if args.job_backend:
        overrides["job_backend"] = args.job_backend
    if getattr(args, "workers", None):
        overrides["workers"] = args.workers
    if getattr(args, "forwarded_allow_ips", None) is not None:
        overrides["forwarded_allow_ips"] = args.forwarded_allow_ips
    return Settings(**overrides)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from orbitcal.cli import CliError
    from service.app import create_app
    from service.auth import is_loopback
    from service.http import uvicorn_options
    from service.logs import redact_url

    settings = settings_from_args(args)
    if not settings.auth:
        if not is_loopback(args.host):
            raise CliError(f"--no-auth is refused on {args.host}: bind to 127.0.0.1")
        print(
            "orbitcal serve: WARNING: AUTHENTICATION IS OFF — every local caller is admin",
            file=sys.stderr,
        )
    elif settings.admin_key is None:
        print(
            "orbitcal serve: no ORBITCAL_ADMIN_KEY set: set one to create API keys",
            file=sys.stderr,
        )
    app = create_app(settings)
    print(
        f"orbitcal serve: http://{args.host}:{args.port}  database "
        f"{redact_url(settings.database_url)}  dashboard /dashboard  API /docs",
        file=sys.stderr,
    )
    if settings.workers > 1:
        # Each worker process builds its own app from the environment: hand the options on.
        import os

        os.environ.update(
            {
                "ORBITCAL_BIND_HOST": settings.bind_host,
                "ORBITCAL_DATABASE_URL": settings.database_url,
                "ORBITCAL_AUTH": str(settings.auth).lower(),
                "ORBITCAL_SCHEDULER": str(settings.scheduler).lower(),
                "ORBITCAL_JOB_BACKEND": settings.job_backend,
                "ORBITCAL_WORKERS": str(settings.workers),
                "ORBITCAL_FORWARDED_ALLOW_IPS": settings.forwarded_allow_ips,
            }
        )
        uvicorn.run(
            "service.app:app_from_environment",
            factory=True,
            workers=settings.workers,
            host=args.host,
            port=args.port,
            log_level="warning",
            access_log=False,
            # uvicorn kills a worker that does not answer its health ping within this time; a
            # retraining or diagnosis holding the GIL on a busy machine must not cost the worker
            timeout_worker_healthcheck=120,
            **uvicorn_options(settings),
        )
        return 0
    uvicorn.run(
        app,
        host=args.host,
        port=args.port,
        log_level="warning",
        access_log=False,
        **uvicorn_options(settings),
    )
    return 0
