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
        description="Run the orbitcal HTTP service with uvicorn (one process; scheduler inside).",
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
    return Settings(**overrides)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from orbitcal.cli import CliError
    from service.app import create_app
    from service.auth import is_loopback
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
    uvicorn.run(app, host=args.host, port=args.port, log_level="warning", access_log=False)
    return 0
