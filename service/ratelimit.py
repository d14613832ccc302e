"""Rate limiting (ASGI middleware): a token bucket per API key, and one per client address for
failed authentication, answered with 429 and ``Retry-After``.

Two kinds of bucket:

* **requests**: each ``X-API-Key`` (held as its sha256, never in clear) gets ``burst`` requests
  refilled at ``rate_per_s``; requests without a key are bucketed per client address.
* **failed authentication**: every ``401`` answer takes a token from the bucket of the client's
  address (``auth_fail_burst``, refilled at ``auth_fail_per_s``). While that bucket is empty,
  the request is marked (:data:`AUTH_THROTTLE`) and goes on to authentication, which answers a
  failure 429 instead of 401 and lets a valid key through: one cron job with an expired key
  must not lock its whole host (or everyone behind one proxy) out. A client sending a fresh
  wrong key each time cannot bypass the limiter by getting a fresh request bucket per key: its
  failures are counted where it cannot change them, its address (the real one behind a trusted
  proxy, ``ORBITCAL_FORWARDED_ALLOW_IPS``).

``/healthz`` is never limited. An empty bucket answers ``429`` with ``Retry-After`` (whole seconds
until one request is allowed again).

Where the buckets live: in the process (:class:`MemoryBuckets`, the single-process default), or
in Redis (:class:`RedisBuckets`, ``ORBITCAL_RATE_LIMIT_REDIS_URL``) so that several API processes
(``orbitcal serve --workers N``, or replicas behind a proxy) share one set of buckets and a client
gets the configured rate in total, not once per process. The Redis buckets are updated by one Lua
script per request (atomic on the server) with the Redis server's clock, so processes need not
agree on time. When Redis cannot be reached the request is let through and a warning logged:
the limiter protects the service, it must not become the reason it is down.

Settings: ``ORBITCAL_RATE_LIMIT_PER_S`` (0 turns the limiter off), ``ORBITCAL_RATE_LIMIT_BURST``,
``ORBITCAL_AUTH_FAIL_PER_S``, ``ORBITCAL_AUTH_FAIL_BURST``, ``ORBITCAL_RATE_LIMIT_REDIS_URL``.
"""

from __future__ import annotations

import hashlib
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = [
    "AUTH_THROTTLE",
    "Buckets",
    "MemoryBuckets",
    "RateLimit",
    "RedisBuckets",
    "retry_after_s",
]

#: Key of ``scope["state"]`` set while the client's failed-authentication bucket is empty: the
#: 429 detail and the seconds until a failure is allowed again (read by ``service.auth``).
AUTH_THROTTLE = "orbitcal.auth_throttle"

log = logging.getLogger("orbitcal.service.ratelimit")

#: Buckets kept at most in one process; full (idle) buckets are dropped first when exceeded.
MAX_BUCKETS = 100_000


class Buckets(Protocol):
    """A store of token buckets shared by whoever holds the same store."""

    async def take(self, identity: str, rate_per_s: float, burst: float, *, cost: float) -> float:
        """Take ``cost`` tokens (0 only looks); return 0 if allowed, else seconds until allowed."""
        ...

    async def close(self) -> None: ...


class MemoryBuckets:
    """Buckets of this process (a dict under a lock)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        #: identity -> (tokens, last time, rate [1/s], burst)
        self._buckets: dict[str, tuple[float, float, float, float]] = {}
        self._lock = threading.Lock()

    def take_now(self, identity: str, rate_per_s: float, burst: float, *, cost: float) -> float:
        now = self.clock()
        with self._lock:
            tokens, last, _, _ = self._buckets.get(identity, (burst, now, rate_per_s, burst))
            tokens = min(burst, tokens + (now - last) * rate_per_s)
            if tokens >= 1.0:
                tokens -= cost
                wait = 0.0
            else:
                wait = (1.0 - tokens) / rate_per_s
            self._buckets[identity] = (tokens, now, rate_per_s, burst)
            if len(self._buckets) > MAX_BUCKETS:
                self._drop_full(now)
        return wait

    def _drop_full(self, now: float) -> None:
        full = [k for k, (t, at, r, b) in self._buckets.items() if t + (now - at) * r >= b]
        for k in full:
            del self._buckets[k]

    async def take(self, identity: str, rate_per_s: float, burst: float, *, cost: float) -> float:
        return self.take_now(identity, rate_per_s, burst, cost=cost)

    async def close(self) -> None:
        return None


#: KEYS[1] bucket; ARGV rate [1/s], burst, cost, ttl [s]. Returns the wait [µs] (0: allowed).
_LUA_TAKE = """
local now_parts = redis.call('TIME')
local now = tonumber(now_parts[1]) + tonumber(now_parts[2]) / 1e6
local rate = tonumber(ARGV[1])
local burst = tonumber(ARGV[2])
local cost = tonumber(ARGV[3])
local state = redis.call('HMGET', KEYS[1], 't', 'at')
local tokens = tonumber(state[1])
local last = tonumber(state[2])
if tokens == nil then tokens = burst; last = now end
tokens = math.min(burst, tokens + math.max(0, now - last) * rate)
local wait = 0
if tokens >= 1 then
  tokens = tokens - cost
else
  wait = (1 - tokens) / rate
end
redis.call('HSET', KEYS[1], 't', tostring(tokens), 'at', tostring(now))
redis.call('EXPIRE', KEYS[1], tonumber(ARGV[4]))
return math.floor(wait * 1e6)
"""


class RedisBuckets:
    """Buckets in Redis, shared by every API process configured with the same URL and prefix."""

    def __init__(self, url: str, *, prefix: str = "orbitcal:ratelimit:") -> None:
        import redis.asyncio as aioredis

        self.url = url
        self.prefix = prefix
        self._client: Any = aioredis.Redis.from_url(url, socket_timeout=0.5)
        self._script: Any = self._client.register_script(_LUA_TAKE)
        self._warned_at = 0.0

    async def take(self, identity: str, rate_per_s: float, burst: float, *, cost: float) -> float:
        ttl_s = max(1, math.ceil(burst / rate_per_s) + 1)  # a full bucket needs no key
        try:
            wait_us = await self._script(
                keys=[self.prefix + identity], args=[rate_per_s, burst, cost, ttl_s]
            )
        except Exception as exc:  # any Redis failure: fail open, loudly
            now = time.monotonic()
            if now - self._warned_at > 10.0:
                self._warned_at = now
                log.warning(
                    "rate-limit store unreachable; requests pass unlimited",
                    extra={"error": type(exc).__name__},
                )
            return 0.0
        return float(wait_us) / 1e6

    async def close(self) -> None:
        await self._client.aclose()


def retry_after_s(wait_s: float) -> int:
    """Whole seconds of ``Retry-After`` for a wait [s] (at least 1)."""
    return max(1, math.ceil(wait_s))


def _too_many(detail: str, wait_s: float) -> JSONResponse:
    seconds = retry_after_s(wait_s)
    return JSONResponse(
        {"detail": f"{detail}; retry after {seconds} s", "errors": []},
        status_code=429,
        headers={"Retry-After": str(seconds)},
    )


class RateLimit:
    """The middleware; ``store`` defaults to this process's :class:`MemoryBuckets`."""

    def __init__(
        self,
        app: ASGIApp,
        *,
        rate_per_s: float,
        burst: int,
        auth_fail_per_s: float = 1.0,
        auth_fail_burst: int = 100,
        store: Buckets | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.app = app
        self.rate = float(rate_per_s)
        self.burst = float(max(1, burst))
        self.fail_rate = float(auth_fail_per_s)
        self.fail_burst = float(max(1, auth_fail_burst))
        self.store: Buckets = store if store is not None else MemoryBuckets(clock)

    @staticmethod
    def _identities(scope: Scope) -> tuple[str, str]:
        """``(request bucket, failed-authentication bucket)`` of a request."""
        client = scope.get("client") or ("?", 0)
        address = f"addr:{client[0]}"
        for name, value in scope.get("headers", []):
            if name == b"x-api-key":
                return "key:" + hashlib.sha256(value).hexdigest(), "authfail:" + address
        return address, "authfail:" + address

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or self.rate <= 0 or scope.get("path") == "/healthz":
            await self.app(scope, receive, send)
            return
        requests, failures = self._identities(scope)
        if self.fail_rate > 0:
            wait = await self.store.take(failures, self.fail_rate, self.fail_burst, cost=0.0)
            if wait > 0:  # authentication refuses failures with 429; valid keys pass
                scope.setdefault("state", {})[AUTH_THROTTLE] = (
                    f"too many failed authentications from this address (limit "
                    f"{self.fail_rate:g}/s after {self.fail_burst:g})",
                    wait,
                )
        wait = await self.store.take(requests, self.rate, self.burst, cost=1.0)
        if wait > 0:
            response = _too_many(f"rate limit of {self.rate:g} requests/s per key exceeded", wait)
            await response(scope, receive, send)
            return
        status = 0

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            if status == 401 and self.fail_rate > 0:
                await self.store.take(failures, self.fail_rate, self.fail_burst, cost=1.0)
