"""The service's own ASGI middleware: an access log line per request, and the body-size limit.

(The others: ``service.ratelimit.RateLimit``, ``service.http.HeaderChecks`` and uvicorn's
``ProxyHeadersMiddleware``; their order is set in ``service.app``.)
"""

from __future__ import annotations

import logging
import time
from typing import Any

from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

__all__ = ["AccessLog", "BodyLimit"]


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
