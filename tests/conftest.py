"""Shared fixtures: paths to reference data and service availability.

Tests that need the PostgreSQL/Redis/RabbitMQ servers are marked ``services``. Outside CI they skip
when a server is absent; in CI (``CI=true``) they fail instead, so they never skip quietly there.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
AUTHORITIES = REPO_ROOT / "tests" / "authorities"
SHARED_DATA = Path(os.environ.get("ORBITCAL_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))
IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}


def port_open(host: str, port: int, timeout_s: float = 0.5) -> bool:
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def require_service(name: str, port: int) -> None:
    """Skip (locally) or fail (in CI) when a server is not listening on 127.0.0.1:port."""
    if port_open("127.0.0.1", port):
        return
    message = f"{name} is not listening on 127.0.0.1:{port}"
    if IN_CI:
        pytest.fail(message + " (CI must run this test)")
    pytest.skip(message)


@pytest.fixture(scope="session")
def authorities() -> Path:
    return AUTHORITIES


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared reference data not found at {SHARED_DATA} (set ORBITCAL_SHARED_DATA)")
    return SHARED_DATA


@pytest.fixture(autouse=True, scope="session")
def _torch_single_thread() -> None:
    try:
        import torch
    except ImportError:  # pragma: no cover
        return
    torch.set_num_threads(1)
