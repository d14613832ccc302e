"""Shared route dependencies and helpers.

Dependencies are ``async def`` so that FastAPI calls them on the event loop (a plain ``def``
dependency costs a thread-pool round trip per request).
"""

from __future__ import annotations

import time
from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import Depends, HTTPException, Request
from sqlalchemy.engine import Connection, Engine

from service.settings import Settings
from service.state import ServiceState, service_state
from service.storage import Spacecraft

__all__ = [
    "MAX_ROW_ID",
    "EngineDep",
    "SettingsDep",
    "StateDep",
    "get_spacecraft",
    "iso",
    "iso_or_none",
]

#: The largest id a table's ``sa.Integer`` primary key holds (PostgreSQL ``integer``, 32 bits):
#: integer ids in paths and bodies are validated against it (422), so a huge id is never sent to
#: the database (it answered 500: "integer out of range", SQLite's OverflowError).
MAX_ROW_ID = 2**31 - 1


async def _engine(request: Request) -> Engine:
    return service_state(request).engine


async def _settings(request: Request) -> Settings:
    return service_state(request).settings


async def _state(request: Request) -> ServiceState:
    return service_state(request)


EngineDep = Annotated[Engine, Depends(_engine)]
SettingsDep = Annotated[Settings, Depends(_settings)]
StateDep = Annotated[ServiceState, Depends(_state)]


def iso(t: float) -> str:
    """POSIX seconds → ISO-8601 UTC with ``Z`` (millisecond precision)."""
    whole = int(t // 1)
    return (
        time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(whole)) + f".{int((t - whole) * 1000):03d}Z"
    )


def iso_or_none(t: float | None) -> str | None:
    return None if t is None else iso(t)


def get_spacecraft(conn: Connection, spacecraft_id: str) -> Any:
    row = conn.execute(sa.select(Spacecraft).where(Spacecraft.id == spacecraft_id)).first()
    if row is None:
        raise HTTPException(status_code=404, detail=f"unknown spacecraft {spacecraft_id!r}")
    return row
