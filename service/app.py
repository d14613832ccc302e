"""The application factory: ``create_app(settings)`` builds a FastAPI app; its lifespan opens the
database (running migrations), the job runner and the scheduler. Nothing happens at import time.

``create_app`` reads as its parts: :func:`refuse_unsafe_settings`, :func:`new_state`,
:func:`make_lifespan`, :func:`new_app`, :func:`add_middleware`,
``service.handlers.add_exception_handlers`` and :func:`include_routes`.
"""

from __future__ import annotations

import fcntl
import hashlib
import logging
import tempfile
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import IO, Any

from fastapi import FastAPI
from uvicorn.middleware.proxy_headers import ProxyHeadersMiddleware

import orbitcal
from service.auth import is_loopback
from service.handlers import add_exception_handlers
from service.health_worker import HealthWorker
from service.http import HeaderChecks
from service.jobs import FitFunction, InlineRunner, JobRunner, recover_interrupted
from service.logs import configure_logging, redact_url
from service.metrics import Metrics
from service.middleware import AccessLog, BodyLimit
from service.ratelimit import Buckets, MemoryBuckets, RateLimit, RedisBuckets
from service.routes import (
    calibrations,
    dashboard,
    exports,
    health,
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
from service.state import ServiceState
from service.storage import hash_key, make_engine, upgrade

__all__ = ["create_app"]

log = logging.getLogger("orbitcal.service")

RunnerFactory = Callable[[Any, Settings], JobRunner]


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


def deployment_id(settings: Settings) -> str:
    """One deployment = one database: processes sharing it share the rate-limit buckets and elect
    one of them for the per-deployment duties (the digest keeps deployments apart without putting
    the database URL into Redis or a file name)."""
    return hashlib.sha256(settings.database_url.encode()).hexdigest()[:16]


def refuse_unsafe_settings(settings: Settings) -> None:
    """Refuse (``ValueError``) configurations that would be unsafe rather than start with them."""
    if not settings.auth and not is_loopback(settings.bind_host):
        raise ValueError(
            f"refusing to run without authentication on {settings.bind_host}: "
            "bind to 127.0.0.1 or set ORBITCAL_ADMIN_KEY and leave ORBITCAL_AUTH on"
        )
    if settings.workers > 1 and settings.rate_limit_per_s > 0 and not settings.rate_limit_redis_url:
        raise ValueError(
            f"{settings.workers} API processes would each keep their own rate-limit buckets: "
            "set ORBITCAL_RATE_LIMIT_REDIS_URL (shared buckets) or ORBITCAL_RATE_LIMIT_PER_S=0"
        )


def new_state(settings: Settings) -> ServiceState:
    """The app's state before the lifespan: settings, admin key hash, rate-limit store, caches."""
    deployment = deployment_id(settings)
    store: Buckets = (
        RedisBuckets(settings.rate_limit_redis_url, prefix=f"orbitcal:ratelimit:{deployment}:")
        if settings.rate_limit_redis_url
        else MemoryBuckets()
    )
    admin_hash = hash_key(settings.admin_key.get_secret_value()) if settings.admin_key else None
    return ServiceState.new(settings, admin_key_hash=admin_hash, rate_limit_store=store)


def _job_runner(
    engine: Any,
    settings: Settings,
    state: ServiceState,
    *,
    fit: FitFunction | None,
    runner: RunnerFactory | None,
) -> JobRunner:
    if runner is not None:
        return runner(engine, settings)
    if settings.job_backend == "celery":
        from service.celery_app import CeleryRunner

        return CeleryRunner(settings)

    def on_done(status: str, seconds: float) -> None:
        state.metrics.retrain_seconds.labels(status).observe(seconds)
        state.calibration_cache.clear()  # a promotion shows at once in this process

    return InlineRunner(engine, settings, fit=fit, on_done=on_done)


def make_lifespan(
    settings: Settings,
    state: ServiceState,
    *,
    fit: FitFunction | None = None,
    runner: RunnerFactory | None = None,
) -> Callable[[FastAPI], Any]:
    """The lifespan: open the database, the job runner, the scheduler; close them at the end."""
    deployment = deployment_id(settings)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        engine = make_engine(
            settings.database_url,
            sqlite_synchronous=settings.sqlite_synchronous,
            sqlite_max_bytes=settings.sqlite_max_bytes,
        )
        migrating = _deployment_lock(deployment + "-migrate", wait=True)  # workers start at once
        try:
            upgrade(engine)
        finally:
            if migrating is not None:
                migrating.close()
        state.metrics = Metrics(engine)
        job_runner = _job_runner(engine, settings, state, fit=fit, runner=runner)
        # Duties of one process per deployment (several uvicorn workers share one database):
        # the first process to take the lock recovers interrupted inline jobs and runs the
        # scheduler; the others serve requests and run the jobs they were asked for.
        leader = _deployment_lock(deployment)
        if settings.job_backend == "inline" and runner is None and leader is not None:
            for job_id in recover_interrupted(engine):
                job_runner.submit(job_id)
        scheduler = FleetScheduler(engine, settings, job_runner)
        if settings.scheduler and leader is not None:
            scheduler.start()
        health_worker = HealthWorker(engine, settings, job_runner)
        state.open(
            engine=engine,
            metrics=state.metrics,
            runner=job_runner,
            scheduler=scheduler,
            leader=leader is not None,
            health=health_worker,
        )
        log.info(
            "service started",
            extra={
                "database": redact_url(settings.database_url),
                "job_backend": settings.job_backend,
                "scheduler": settings.scheduler,
                "auth": settings.auth,
            },
        )
        try:
            yield
        finally:
            state.diagnoses.shutdown()
            health_worker.shutdown()
            scheduler.shutdown()
            job_runner.shutdown()
            engine.dispose()
            await state.rate_limit_store.close()
            if leader is not None:
                leader.close()  # releases the lock

    return lifespan


def new_app(lifespan: Callable[[FastAPI], Any]) -> FastAPI:
    """The FastAPI object with the answers every route may give documented once."""
    return FastAPI(
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
                "description": "per-key rate limit exceeded, or too many failed "
                "authentications from this address",
                "headers": {"Retry-After": {"schema": {"type": "integer"}}},
            },
            503: {
                "model": ErrorPublic,
                "description": "database unavailable or a resource of the server exhausted "
                "(too many open files, no free connection): nothing was stored, or (connection "
                "lost during commit) the outcome is unknown and re-sending is safe",
                "headers": {"Retry-After": {"schema": {"type": "integer"}}},
            },
            507: {
                "model": ErrorPublic,
                "description": "insufficient storage: the server's disk is full or the database "
                "file reached its file-size limit; nothing was stored",
                "headers": {"Retry-After": {"schema": {"type": "integer"}}},
            },
        },
    )


def add_middleware(app: FastAPI, settings: Settings, state: ServiceState) -> None:
    """The middleware stack; the last added is the outermost (the first a request meets).

    Outside in: trusted-proxy headers (the client address everything below sees), the header
    count and the body's framing, the rate limiter (a throttled caller costs no body read), the
    access log, the body size limit, the calibration fast path.
    """
    app.add_middleware(calibrations.CalibrationFastPath, state=state)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    app.add_middleware(AccessLog)
    if settings.rate_limit_per_s > 0:
        app.add_middleware(
            RateLimit,
            rate_per_s=settings.rate_limit_per_s,
            burst=settings.rate_limit_burst,
            auth_fail_per_s=settings.auth_fail_per_s,
            auth_fail_burst=settings.auth_fail_burst,
            store=state.rate_limit_store,
        )
    app.add_middleware(HeaderChecks, limit=settings.max_header_count)
    if settings.forwarded_allow_ips.strip():
        app.add_middleware(
            ProxyHeadersMiddleware,  # type: ignore[arg-type]
            trusted_hosts=settings.forwarded_allow_ips,
        )


def include_routes(app: FastAPI) -> None:
    modules = (ops, spacecraft, telemetry, quarantine, calibrations, health, jobs, keys, dashboard)
    for module in modules:
        app.include_router(module.router)
    app.include_router(exports.router)  # issue 21: /calibrations/{version}[?format=F]


def create_app(
    settings: Settings | None = None,
    *,
    fit: FitFunction | None = None,
    runner: RunnerFactory | None = None,
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
    refuse_unsafe_settings(settings)
    state = new_state(settings)
    app = new_app(make_lifespan(settings, state, fit=fit, runner=runner))
    app.state = state
    if not settings.auth:
        log.warning(
            "AUTHENTICATION IS OFF: every caller on %s is admin. Only for local use.",
            settings.bind_host,
        )
    elif state.admin_key_hash is None:
        log.warning("no ORBITCAL_ADMIN_KEY set: no key can be created until one is")
    add_middleware(app, settings, state)
    add_exception_handlers(app)
    include_routes(app)
    return app


def app_from_environment() -> FastAPI:
    """``create_app(Settings())``: the factory uvicorn imports in each worker process."""
    return create_app(Settings())
