"""The application factory: ``create_app(settings)`` builds a FastAPI app; its lifespan opens the
database (running migrations), the job runner and the scheduler. Nothing happens at import time.
"""

from __future__ import annotations

import asyncio
import fcntl
import hashlib
import logging
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import IO, Any

import sqlalchemy as sa
from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

import orbitcal
from orbitcal.errors import OrbitcalError
from service.auth import is_loopback
from service.diagnosis_cache import DiagnosisCache
from service.jobs import FitFunction, InlineRunner, JobRunner, recover_interrupted
from service.logs import configure_logging, redact_url
from service.metrics import Metrics
from service.ratelimit import Buckets, MemoryBuckets, RateLimit, RedisBuckets
from service.routes import (
    calibrations,
    dashboard,
    jobs,
    keys,
    ops,
    quarantine,
    spacecraft,
    telemetry,
)
from service.scheduler import FleetScheduler
from service.schemas import ErrorPublic
from service.settings import Settings
from service.storage import CommitOutcomeUnknown, hash_key, make_engine, upgrade

__all__ = ["create_app"]

log = logging.getLogger("orbitcal.service")


class AccessLog:
    """One structured log line per request: method, path (no query string), status, duration."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.log = logging.getLogger("orbitcal.service.access")

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500

        async def send_wrapper(message: Any) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            level = logging.WARNING if status >= 500 else logging.INFO
            if self.log.isEnabledFor(level):
                self.log.log(
                    level,
                    "request",
                    extra={
                        "method": scope["method"],
                        "path": scope["path"],
                        "status": status,
                        "ms": round((time.perf_counter() - start) * 1e3, 2),
                    },
                )


class BodyLimit:
    """413 before reading a body whose declared length exceeds the limit (ASGI middleware)."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            for name, value in scope.get("headers", []):
                if name == b"content-length":
                    if not value.isdigit() or int(value) > self.limit:
                        response = JSONResponse(
                            {
                                "detail": f"body of {value.decode()} bytes exceeds {self.limit}",
                                "errors": [],
                            },
                            status_code=413,
                            headers={"Connection": "close"},  # do not drain the body
                        )
                        await response(scope, receive, send)
                        return
                    break
        await self.app(scope, receive, send)


def _error(
    status: int,
    detail: str,
    errors: list[dict[str, Any]] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    return JSONResponse(
        {"detail": detail, "errors": errors or []}, status_code=status, headers=headers
    )


def _deployment_lock(deployment: str, *, wait: bool = False) -> IO[bytes] | None:
    """An exclusive lock of this machine's processes serving one database, or None if taken.

    ``flock`` on ``<tmp>/orbitcal-<digest of the database URL>.lock``; the kernel releases it
    when the holder exits, however it exits, so a restarted process can take it over. With
    ``wait`` the call blocks until the lock is free (closing the handle releases it).
    """
    path = Path(tempfile.gettempdir()) / f"orbitcal-{deployment}.lock"
    handle = path.open("ab")
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return None
    return handle


def create_app(
    settings: Settings | None = None,
    *,
    fit: FitFunction | None = None,
    runner: Callable[[Any, Settings], JobRunner] | None = None,
) -> FastAPI:
    """Build the service.

    Parameters
    ----------
    settings
        Defaults to ``Settings()`` (the ``ORBITCAL_*`` environment).
    fit
        Replaces the calibration fit of inline jobs (tests inject a deliberately worse fitter).
    runner
        ``runner(engine, settings) -> JobRunner``; default: inline thread pool, or Celery when
        ``settings.job_backend == "celery"``.
    """
    settings = settings or Settings()
    configure_logging(settings.log_level)
    if not settings.auth and not is_loopback(settings.bind_host):
        raise ValueError(
            f"refusing to run without authentication on {settings.bind_host}: "
            "bind to 127.0.0.1 or set ORBITCAL_ADMIN_KEY and leave ORBITCAL_AUTH on"
        )

    # One deployment = one database: processes sharing it share the rate-limit buckets and elect
    # one of them for the per-deployment duties (the digest keeps deployments apart without
    # putting the database URL into Redis or a file name).
    deployment = hashlib.sha256(settings.database_url.encode()).hexdigest()[:16]

    if settings.workers > 1 and settings.rate_limit_per_s > 0 and not settings.rate_limit_redis_url:
        raise ValueError(
            f"{settings.workers} API processes would each keep their own rate-limit buckets: "
            "set ORBITCAL_RATE_LIMIT_REDIS_URL (shared buckets) or ORBITCAL_RATE_LIMIT_PER_S=0"
        )

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        engine = make_engine(settings.database_url, sqlite_synchronous=settings.sqlite_synchronous)
        migrating = _deployment_lock(deployment + "-migrate", wait=True)  # workers start at once
        try:
            upgrade(engine)
        finally:
            if migrating is not None:
                migrating.close()
        metrics = Metrics(engine)
        app.state.engine = engine
        app.state.metrics = metrics

        def on_done(status: str, seconds: float) -> None:
            metrics.retrain_seconds.labels(status).observe(seconds)
            app.state.calibration_cache.clear()  # a promotion shows at once in this process

        job_runner: JobRunner
        if runner is not None:
            job_runner = runner(engine, settings)
        elif settings.job_backend == "celery":
            from service.celery_app import CeleryRunner

            job_runner = CeleryRunner(settings)
        else:
            job_runner = InlineRunner(engine, settings, fit=fit, on_done=on_done)
        app.state.runner = job_runner
        # Duties of one process per deployment (several uvicorn workers share one database):
        # the first process to take the lock recovers interrupted inline jobs and runs the
        # scheduler; the others serve requests and run the jobs they were asked for.
        leader = _deployment_lock(deployment)
        app.state.leader = leader is not None
        if settings.job_backend == "inline" and runner is None and leader is not None:
            for job_id in recover_interrupted(engine):
                job_runner.submit(job_id)
        scheduler = FleetScheduler(engine, settings, job_runner)
        app.state.scheduler = scheduler
        if settings.scheduler and leader is not None:
            scheduler.start()
        log.info(
            "service started",
            extra={
                "database": redact_url(settings.database_url),
                "job_backend": settings.job_backend,
                "scheduler": settings.scheduler,
                "auth": settings.auth,
            },
        )
        app.state.diagnoses.start()
        try:
            yield
        finally:
            app.state.diagnoses.shutdown()
            scheduler.shutdown()
            job_runner.shutdown()
            engine.dispose()
            await rate_store.close()
            if leader is not None:
                leader.close()  # releases the lock

    app = FastAPI(
        title="orbitcal",
        version=orbitcal.__version__,
        summary="On-orbit magnetometer calibration: telemetry ingest, retraining, calibrations.",
        lifespan=lifespan,
        # /docs and /redoc are served by routes/dashboard.py from local assets (no CDN)
        docs_url=None,
        redoc_url=None,
        # Answers every route may give, documented once (their body is ErrorPublic, not
        # FastAPI's default HTTPValidationError): found by tests/reliability/test_fuzz_openapi.py.
        responses={
            400: {"model": ErrorPublic, "description": "unreadable body"},
            401: {"model": ErrorPublic, "description": "missing, unknown or revoked X-API-Key"},
            422: {"model": ErrorPublic, "description": "invalid parameter or body field"},
            429: {
                "model": ErrorPublic,
                "description": "per-key rate limit exceeded",
                "headers": {"Retry-After": {"schema": {"type": "integer"}}},
            },
            503: {
                "model": ErrorPublic,
                "description": "database unavailable: nothing was stored, or (connection lost "
                "during commit) the outcome is unknown and re-sending is safe",
                "headers": {"Retry-After": {"schema": {"type": "integer"}}},
            },
        },
    )
    app.state.settings = settings
    app.state.admin_key_hash = (
        hash_key(settings.admin_key.get_secret_value()) if settings.admin_key else None
    )
    app.state.diagnoses = DiagnosisCache()
    app.state.key_cache = {}
    app.state.key_lock = asyncio.Lock()
    app.state.calibration_cache = {}
    app.state.calibration_locks = {}
    if not settings.auth:
        log.warning(
            "AUTHENTICATION IS OFF: every caller on %s is admin. Only for local use.",
            settings.bind_host,
        )
    elif app.state.admin_key_hash is None:
        log.warning("no ORBITCAL_ADMIN_KEY set: no key can be created until one is")

    rate_store: Buckets = (
        RedisBuckets(settings.rate_limit_redis_url, prefix=f"orbitcal:ratelimit:{deployment}:")
        if settings.rate_limit_redis_url
        else MemoryBuckets()
    )
    app.state.rate_limit_store = rate_store
    app.add_middleware(calibrations.CalibrationFastPath, state=app.state)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    app.add_middleware(AccessLog)
    if settings.rate_limit_per_s > 0:  # outermost: a throttled caller costs no body read
        app.add_middleware(
            RateLimit,
            rate_per_s=settings.rate_limit_per_s,
            burst=settings.rate_limit_burst,
            auth_fail_per_s=settings.auth_fail_per_s,
            auth_fail_burst=settings.auth_fail_burst,
            store=rate_store,
        )

    @app.exception_handler(HTTPException)
    async def _http_error(_request: Request, exc: HTTPException) -> JSONResponse:
        return _error(exc.status_code, str(exc.detail), headers=dict(exc.headers or {}))

    @app.exception_handler(OrbitcalError)
    async def _library_error(_request: Request, exc: OrbitcalError) -> JSONResponse:
        # The one place where the library's error tree becomes HTTP (orbitcal/errors.py has
        # the table): routes let these propagate instead of catching built-in exception types.
        item: dict[str, Any] = {"reason": str(exc)}
        for name in ("field", "row"):
            value = getattr(exc, name, None)
            if value is not None:
                item[name] = value
        body_extra: dict[str, Any] = dict(getattr(exc, "body_extra", None) or {})
        response = _error(exc.http_status, str(exc), [item])
        if body_extra:
            response = JSONResponse(
                {"detail": str(exc), "errors": [item], **body_extra},
                status_code=exc.http_status,
            )
        if exc.http_status == 503:
            response.headers["Retry-After"] = "60"
        return response

    @app.exception_handler(RequestValidationError)
    async def _validation_error(_request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            {"field": ".".join(str(p) for p in e.get("loc", ())), "reason": e.get("msg", "")}
            for e in exc.errors()
        ]
        return _error(
            422,
            "invalid request: " + "; ".join(f"{e['field']}: {e['reason']}" for e in errors),
            errors,
        )

    @app.exception_handler(CommitOutcomeUnknown)
    async def _commit_unknown(_request: Request, exc: CommitOutcomeUnknown) -> JSONResponse:
        log.warning("database connection lost during commit")
        return _error(
            503,
            "database connection lost while committing: the request may or may not have been "
            "stored; re-send it (telemetry ingest is idempotent: duplicates change nothing)",
            headers={"Retry-After": "5"},
        )

    def _unavailable(exc: sa.exc.DBAPIError, what: str) -> JSONResponse:
        log.warning(what, extra={"error": type(exc.orig).__name__})
        return _error(
            503,
            "database unavailable, nothing was stored; retry later",
            headers={"Retry-After": "5"},
        )

    async def _db_unavailable(_request: Request, exc: sa.exc.DBAPIError) -> JSONResponse:
        return _unavailable(exc, "database unavailable")

    app.add_exception_handler(sa.exc.OperationalError, _db_unavailable)  # type: ignore[arg-type]
    app.add_exception_handler(sa.exc.InterfaceError, _db_unavailable)  # type: ignore[arg-type]

    @app.exception_handler(sa.exc.DBAPIError)
    async def _db_error(_request: Request, exc: sa.exc.DBAPIError) -> JSONResponse:
        if exc.connection_invalidated:
            return _unavailable(exc, "database connection lost")
        log.error("database error", exc_info=exc)
        return _error(500, "internal error (logged)")

    @app.exception_handler(Exception)
    async def _unexpected(_request: Request, exc: Exception) -> JSONResponse:
        log.error("unexpected error", exc_info=exc)
        return _error(500, "internal error (logged)")

    for module in (ops, spacecraft, telemetry, quarantine, calibrations, jobs, keys, dashboard):
        app.include_router(module.router)
    return app


def app_from_environment() -> FastAPI:
    """``create_app(Settings())``: the factory uvicorn imports in each worker process."""
    return create_app(Settings())
