"""Per-key rate limiting: a token bucket per API key (ASGI middleware), answered with 429.

Each ``X-API-Key`` (held as its sha256, never in clear) gets a bucket of ``burst`` requests that
refills at ``rate_per_s``; requests without a key are bucketed per client address. ``/healthz`` is
never limited. An empty bucket answers ``429`` with ``Retry-After`` (whole seconds until one
request is allowed again). Settings: ``ORBITCAL_RATE_LIMIT_PER_S`` (0 turns it off) and
``ORBITCAL_RATE_LIMIT_BURST``. Buckets are per process (one API process per deployment).
"""

from __future__ import annotations

import hashlib
import math
import threading
import time
from collections.abc import Callable

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

__all__ = ["RateLimit"]

#: Buckets kept at most; full (idle) buckets are dropped first when this is exceeded.
MAX_BUCKETS = 100_000


class RateLimit:
    def __init__(
        self,
        app: ASGIApp,
        *,
        rate_per_s: float,
        burst: int,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.app = app
        self.rate = float(rate_per_s)
        self.burst = float(max(1, burst))
        self.clock = clock
        self._buckets: dict[str, tuple[float, float]] = {}  # identity -> (tokens, last time)
        self._lock = threading.Lock()

    def _identity(self, scope: Scope) -> str:
        for name, value in scope.get("headers", []):
            if name == b"x-api-key":
                return "key:" + hashlib.sha256(value).hexdigest()
        client = scope.get("client") or ("?", 0)
        return f"addr:{client[0]}"

    def _take(self, identity: str) -> float:
        """Take one token; return 0 if allowed, else the seconds until a token is available."""
        now = self.clock()
        with self._lock:
            tokens, last = self._buckets.get(identity, (self.burst, now))
            tokens = min(self.burst, tokens + (now - last) * self.rate)
            if tokens >= 1.0:
                self._buckets[identity] = (tokens - 1.0, now)
                wait = 0.0
            else:
                self._buckets[identity] = (tokens, now)
                wait = (1.0 - tokens) / self.rate
            if len(self._buckets) > MAX_BUCKETS:
                full = [
                    k
                    for k, (t, at) in self._buckets.items()
                    if t + (now - at) * self.rate >= self.burst
                ]
                for k in full:
                    del self._buckets[k]
        return wait

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or self.rate <= 0 or scope.get("path") == "/healthz":
            await self.app(scope, receive, send)
            return
        wait = self._take(self._identity(scope))
        if wait > 0:
            seconds = max(1, math.ceil(wait))
            response = JSONResponse(
                {
                    "detail": f"rate limit of {self.rate:g} requests/s per key exceeded; "
                    f"retry after {seconds} s",
                    "errors": [],
                },
                status_code=429,
                headers={"Retry-After": str(seconds)},
            )
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)
