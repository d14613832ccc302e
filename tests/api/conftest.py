"""Fixtures of the service tests (helpers live in service_helpers.py / service_worlds.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from service_helpers import LiveServer, live_server, sqlite_settings


@pytest.fixture
def server(tmp_path: Path) -> Iterator[LiveServer]:
    with live_server(sqlite_settings(tmp_path)) as s:
        yield s
