"""How exceptions become answers: one handler per kind, installed by :func:`add_exception_handlers`.

Every answer has the body ``{"detail": str, "errors": [...]}`` (``schemas.ErrorPublic``). The
kinds, in the order a request meets them:

* ``HTTPException`` (routes, dependencies) and ``RequestValidationError`` (422 naming the field);
* ``OrbitcalError``: the library's error tree becomes HTTP here and only here;
* a client that went away before its request was complete (``ClientDisconnect``, also what a
  request cut by the server's timeouts looks like from inside): logged at INFO as what it is,
  answered 499 (nobody reads it), never an ERROR;
* resources of the machine running out (``ResourceExhausted``, or an ``OSError`` / database
  error whose cause is ENOSPC, EFBIG, EMFILE, …): 507 Insufficient Storage for the disk or the
  file-size limit, 503 for the others, naming the resource; logged at ERROR with its name and
  no traceback;
* the database unreachable or lost during COMMIT: 503 with ``Retry-After``;
* anything else: 500, logged with its traceback.
"""

from __future__ import annotations

import logging
from typing import Any

import sqlalchemy as sa
from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.requests import ClientDisconnect

from orbitcal.errors import OrbitcalError
from service.storage import (
    FILE_SIZE_LIMIT,
    STORAGE_RESOURCES,
    CommitOutcomeUnknown,
    ResourceExhausted,
    resource_problem,
)

__all__ = ["add_exception_handlers", "error_response"]

log = logging.getLogger("orbitcal.service")

#: What the operator should do about each resource, in the 503's detail.
_RESOURCE_ADVICE = {
    "disk": "the server's disk is full",
    FILE_SIZE_LIMIT: "the database file reached the server's file-size limit (ulimit -f)",
    "open files": "the server has too many open files",
    "database connections": "the database has no free connection",
    "memory": "the database is out of memory",
}


def error_response(
    status: int,
    detail: str,
    errors: list[dict[str, Any]] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    return JSONResponse(
        {"detail": detail, "errors": errors or []}, status_code=status, headers=headers
    )


def _resource_exhausted(request: Request, resource: str, exc: BaseException) -> JSONResponse:
    what = _RESOURCE_ADVICE.get(resource, f"the server ran out of {resource}")
    log.error(
        f"resource exhausted: {resource}",
        extra={
            "resource": resource,
            "method": request.method,
            "path": request.url.path,
            "error": f"{type(exc).__name__}: {exc}"[:300],
        },
    )
    # Storage full: 507 Insufficient Storage (RFC 4918), the other resources 503.
    status = 507 if resource in STORAGE_RESOURCES else 503
    return error_response(
        status,
        f"{what} ({resource}): nothing was stored; retry once the operator has freed it",
        [{"reason": f"{resource} exhausted"}],
        headers={"Retry-After": "60"},
    )


async def _http_error(_request: Request, exc: HTTPException) -> JSONResponse:
    return error_response(exc.status_code, str(exc.detail), headers=dict(exc.headers or {}))


async def _library_error(_request: Request, exc: OrbitcalError) -> JSONResponse:
    # The one place where the library's error tree becomes HTTP (orbitcal/errors.py has the
    # table): routes let these propagate instead of catching built-in exception types.
    item: dict[str, Any] = {"reason": str(exc)}
    for name in ("field", "row"):
        value = getattr(exc, name, None)
        if value is not None:
            item[name] = value
    body_extra: dict[str, Any] = dict(getattr(exc, "body_extra", None) or {})
    response = error_response(exc.http_status, str(exc), [item])
    if body_extra:
        response = JSONResponse(
            {"detail": str(exc), "errors": [item], **body_extra}, status_code=exc.http_status
        )
    if exc.http_status == 503:
        response.headers["Retry-After"] = "60"
    return response


async def _validation_error(_request: Request, exc: RequestValidationError) -> JSONResponse:
    errors = [
        {"field": ".".join(str(p) for p in e.get("loc", ())), "reason": e.get("msg", "")}
        for e in exc.errors()
    ]
    return error_response(
        422,
        "invalid request: " + "; ".join(f"{e['field']}: {e['reason']}" for e in errors),
        errors,
    )


async def _client_disconnect(request: Request, _exc: ClientDisconnect) -> Response:
    log.info(
        "client disconnected before its request was complete; nothing was stored",
        extra={"method": request.method, "path": request.url.path},
    )
    return Response(status_code=499)  # nginx's "client closed request"; nobody receives it


async def _resource(request: Request, exc: ResourceExhausted) -> JSONResponse:
    return _resource_exhausted(request, exc.resource, exc)


async def _commit_unknown(_request: Request, exc: CommitOutcomeUnknown) -> JSONResponse:
    log.warning("database connection lost during commit")
    return error_response(
        503,
        "database connection lost while committing: the request may or may not have been "
        "stored; re-send it (telemetry ingest is idempotent: duplicates change nothing)",
        headers={"Retry-After": "5"},
    )


def _unavailable(exc: sa.exc.DBAPIError, what: str) -> JSONResponse:
    log.warning(what, extra={"error": type(exc.orig).__name__})
    return error_response(
        503, "database unavailable, nothing was stored; retry later", headers={"Retry-After": "5"}
    )


async def _db_unavailable(request: Request, exc: sa.exc.DBAPIError) -> JSONResponse:
    resource = resource_problem(exc)
    if resource is not None:
        return _resource_exhausted(request, resource, exc)
    return _unavailable(exc, "database unavailable")


async def _db_error(request: Request, exc: sa.exc.DBAPIError) -> JSONResponse:
    resource = resource_problem(exc)
    if resource is not None:
        return _resource_exhausted(request, resource, exc)
    if exc.connection_invalidated:
        return _unavailable(exc, "database connection lost")
    log.error("database error", exc_info=exc)
    return error_response(500, "internal error (logged)")


async def _os_error(request: Request, exc: OSError) -> JSONResponse:
    resource = resource_problem(exc)
    if resource is not None:
        return _resource_exhausted(request, resource, exc)
    log.error("unexpected error", exc_info=exc)
    return error_response(500, "internal error (logged)")


async def _unexpected(_request: Request, exc: Exception) -> JSONResponse:
    log.error("unexpected error", exc_info=exc)
    return error_response(500, "internal error (logged)")


def add_exception_handlers(app: FastAPI) -> None:
    """Install every handler above on ``app``."""
    handlers: list[tuple[type[Exception], Any]] = [
        (HTTPException, _http_error),
        (OrbitcalError, _library_error),
        (RequestValidationError, _validation_error),
        (ClientDisconnect, _client_disconnect),
        (ResourceExhausted, _resource),
        (CommitOutcomeUnknown, _commit_unknown),
        (sa.exc.OperationalError, _db_unavailable),
        (sa.exc.InterfaceError, _db_unavailable),
        (sa.exc.DBAPIError, _db_error),
        (OSError, _os_error),
        (Exception, _unexpected),
    ]
    for kind, handler in handlers:
        app.add_exception_handler(kind, handler)
