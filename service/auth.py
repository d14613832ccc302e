"""API keys with scopes: ``admin``, ``ingest:<spacecraft|*>``, ``read:<spacecraft|*>``.

Keys are 256-bit random tokens; only their sha256 is stored. The bootstrap admin key comes from
``ORBITCAL_ADMIN_KEY`` and is compared in constant time, never stored. Authentication can be turned
off (``ORBITCAL_AUTH=false``) only when the server is bound to a loopback address.
"""

from __future__ import annotations

import hmac
import ipaddress
import re
import secrets
import time
from dataclasses import dataclass
from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import Depends, HTTPException, Request, Security
from fastapi.concurrency import run_in_threadpool
from fastapi.security import APIKeyHeader

from service.ratelimit import AUTH_THROTTLE, retry_after_s
from service.state import service_state
from service.storage import ApiKey, hash_key, read_tx, write_tx

__all__ = [
    "SCOPE_ACTIONS",
    "SCOPE_RE",
    "SPACECRAFT_ID_PATTERN",
    "SPACECRAFT_ID_RE",
    "Principal",
    "check_key_before_commit",
    "create_key",
    "is_loopback",
    "principal",
    "require_admin",
    "require_scope",
]

#: The grammar of spacecraft ids: 1 to 64 ASCII letters, digits, ``_``, ``.`` and ``-``, starting
#: with a letter or digit. Such an id is one URL path segment as it is (no ``/``, no percent
#: escapes, no control characters or spaces) and can never be ``.`` or ``..``, which clients and
#: proxies would resolve away. ``\Z`` (not ``$``) so that a trailing newline is not allowed.
SPACECRAFT_ID_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}"
SPACECRAFT_ID_RE = re.compile(rf"\A{SPACECRAFT_ID_PATTERN}\Z")
#: The actions a scope may name; ``admin`` stands alone, the others take ``:<spacecraft id|*>``.
SCOPE_ACTIONS = ("ingest", "read")
#: A scope, matched whole: ``admin``, ``ingest:<id|*>`` or ``read:<id|*>``.
SCOPE_RE = re.compile(rf"\A(admin|({'|'.join(SCOPE_ACTIONS)}):(\*|{SPACECRAFT_ID_PATTERN}))\Z")
KEY_PREFIX = "ock_"

#: The ``X-API-Key`` security scheme of the OpenAPI document (the "Authorize" button of /docs).
API_KEY_HEADER = APIKeyHeader(
    name="X-API-Key",
    scheme_name="X-API-Key",
    description="API key (see docs/service.md); any value, or none, when authentication is off",
    auto_error=False,
)


@dataclass(frozen=True)
class Principal:
    """Who is calling: the key's name and scopes (all of them when auth is off)."""

    name: str
    scopes: frozenset[str]

    def allows(self, action: str, spacecraft: str | None) -> bool:
        if "admin" in self.scopes:
            return True
        if action == "admin":
            return False
        if f"{action}:*" in self.scopes:
            return True
        return spacecraft is not None and f"{action}:{spacecraft}" in self.scopes

    def reads_everything(self) -> bool:
        """Whether the key may read every spacecraft (``admin`` or ``read:*``): the scope of
        answers that aggregate over the fleet (``/metrics`` totals)."""
        return "admin" in self.scopes or "read:*" in self.scopes


def is_loopback(host: str) -> bool:
    """Whether the configured bind host (``serve --host``, ``ORBITCAL_BIND_HOST``) is loopback.

    A check of the operator's configuration at start-up, not a request's answer: a host name other
    than ``localhost`` counts as not loopback (the safe side: auth must be on).
    """
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # the stdlib's only way to say "not an IP address"; no answer is built
        return False


def create_key(request: Request, name: str, scopes: list[str]) -> tuple[str, str]:
    """Create a key; return ``(key, prefix)``. The key is shown once and never stored."""
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    prefix = key[:12]
    with write_tx(service_state(request).engine) as conn:
        conn.execute(
            sa.insert(ApiKey).values(
                key_hash=hash_key(key),
                prefix=prefix,
                name=name,
                scopes=sorted(set(scopes)),
                created_at=time.time(),
                revoked=False,
            )
        )
    return key, prefix


def _unauthorised(request: Request, reason: str) -> HTTPException:
    """401, or 429 while the client's address has spent its failed-authentication budget."""
    throttled = (request.scope.get("state") or {}).get(AUTH_THROTTLE)
    if throttled is not None:
        detail, wait_s = throttled
        seconds = retry_after_s(wait_s)
        return HTTPException(
            status_code=429,
            detail=f"{detail}; retry after {seconds} s ({reason})",
            headers={"Retry-After": str(seconds)},
        )
    return HTTPException(status_code=401, detail=reason, headers={"WWW-Authenticate": "X-API-Key"})


def _lookup(engine: Any, key_hash: str) -> Principal | None:
    with read_tx(engine) as conn:
        row = conn.execute(
            sa.select(ApiKey.key_hash, ApiKey.name, ApiKey.scopes, ApiKey.revoked).where(
                ApiKey.key_hash == key_hash
            )
        ).first()
    if row is None or row.revoked or not hmac.compare_digest(row.key_hash, key_hash):
        return None
    return Principal(row.name, frozenset(row.scopes))


async def principal(
    request: Request,
    x_api_key: Annotated[str | None, Security(API_KEY_HEADER)] = None,
) -> Principal:
    """Resolve the caller from ``X-API-Key`` (dependency).

    Lookups are cached for ``key_cache_s`` seconds per key hash (so a revocation takes effect
    within that time); the bootstrap admin key never touches the database.
    """
    state = service_state(request)
    if not state.settings.auth:
        return Principal("anonymous (authentication off)", frozenset({"admin"}))
    if not x_api_key:
        raise _unauthorised(request, "missing X-API-Key header")
    presented = hash_key(x_api_key)
    if state.admin_key_hash is not None and hmac.compare_digest(presented, state.admin_key_hash):
        return Principal("bootstrap admin", frozenset({"admin"}))
    cache = state.key_cache
    hit = cache.get(presented)
    if hit is not None and hit[1] > time.monotonic():
        who = hit[0]
    else:
        async with state.key_lock:  # single flight for concurrent misses
            hit = cache.get(presented)
            if hit is not None and hit[1] > time.monotonic():
                who = hit[0]
            else:
                who = await run_in_threadpool(_lookup, state.engine, presented)
                if len(cache) > 10_000:
                    cache.clear()
                cache[presented] = (who, time.monotonic() + state.settings.key_cache_s)
    if who is None:
        raise _unauthorised(request, "unknown or revoked API key")
    return who


def check_key_before_commit(conn: Any, request: Request) -> None:
    """Raise 401 when the request's key was revoked since the request was authenticated.

    Called inside a write transaction right before it commits (a telemetry upload's body may
    arrive for minutes after its key was checked; issue 44). The key's row is read ``FOR
    SHARE`` where the database has it (PostgreSQL), so a concurrent revocation waits for this
    commit and the upload is wholly before or wholly refused; SQLite serialises writers anyway.
    The bootstrap admin key and authentication off have no row to revoke.
    """
    state = service_state(request)
    presented = request.headers.get("x-api-key")
    if not state.settings.auth or not presented:
        return
    key_hash = hash_key(presented)
    if state.admin_key_hash is not None and hmac.compare_digest(key_hash, state.admin_key_hash):
        return
    revoked = conn.execute(
        sa.select(ApiKey.revoked).where(ApiKey.key_hash == key_hash).with_for_update(read=True)
    ).scalar_one_or_none()
    if revoked is None or revoked:
        state.key_cache.pop(key_hash, None)
        raise HTTPException(
            status_code=401,
            detail="the API key was revoked while the request was being received; "
            "nothing was stored",
            headers={"WWW-Authenticate": "X-API-Key"},
        )


def require_scope(action: str) -> object:
    """Dependency factory: the caller needs ``action`` on the path's ``spacecraft_id``."""

    def dependency(request: Request, who: Annotated[Principal, Depends(principal)]) -> Principal:
        spacecraft = request.path_params.get("spacecraft_id")
        if not who.allows(action, spacecraft):
            target = f"{action}:{spacecraft}" if spacecraft else action
            raise HTTPException(status_code=403, detail=f"this key lacks the scope {target}")
        return who

    return Depends(dependency)


async def require_admin(who: Annotated[Principal, Depends(principal)]) -> Principal:
    if not who.allows("admin", None):
        raise HTTPException(status_code=403, detail="this key lacks the scope admin")
    return who
