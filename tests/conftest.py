"""Shared fixtures: paths to reference data (all inside the repository) and service availability.

Tests that need the PostgreSQL/Redis/RabbitMQ servers are marked ``services``. Outside CI they skip
when a server is absent; in CI (``CI=true``) they fail instead, so they never skip quietly there.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, settings
from shared_worlds import REAL_TLES_FILE, SWARM_A_2022_OMM, SWARM_A_2022_TLE

REPO_ROOT = Path(__file__).resolve().parents[1]
AUTHORITIES = REPO_ROOT / "tests" / "authorities"
IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}

# Hypothesis: one deterministic profile, in CI and on every fresh clone alike. derandomize makes
# the examples a function of the test alone (no random seed, no example database carried between
# runs), so a red run is a real regression that reproduces anywhere. Every failing example ever
# found stays in its test as an explicit @example. HYPOTHESIS_PROFILE=explore searches afresh.
settings.register_profile(
    "ci",
    derandomize=True,
    database=None,
    print_blob=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("explore", deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


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
def real_tles_text() -> str:
    """The 56 real TLE sets of ``tests/authorities/swarm_iss_real_tles.tle`` as one text."""
    return REAL_TLES_FILE.read_text()


@pytest.fixture(scope="session")
def swarm_a_tle(real_tles_text: str) -> str:
    """Swarm A's (NORAD 39452) set in effect on 2022-08-02 00:00 UTC, three-line text."""
    from orbitcal.orbit import select_orbit

    return select_orbit(
        real_tles_text, norad_id=39452, at_utc_s=1_659_398_400.0, prefer_past=True
    ).to_tle_text()


@pytest.fixture
def single_thread_blas():  # type: ignore[no-untyped-def]
    """BLAS on one thread for the test (tiny least-squares fits only contend on a shared 2-core
    machine); use with ``pytestmark = pytest.mark.usefixtures("single_thread_blas")``."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        yield


@pytest.fixture(autouse=True, scope="session")
def _torch_single_thread() -> None:
    try:
        import torch
    except ImportError:  # pragma: no cover
        return
    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def swarm_a_2022_tle() -> str:
    """Swarm A's set of 2022-08-01 as two lines (``shared_worlds.SWARM_A_2022_TLE``)."""
    return SWARM_A_2022_TLE


@pytest.fixture
def swarm_a_2022_omm() -> dict[str, Any]:
    """The same set as a CelesTrak JSON OMM (a fresh copy: tests may alter it)."""
    return dict(SWARM_A_2022_OMM)


@pytest.fixture(scope="session")
def swarm_a_temperature_world() -> tuple[Any, Any]:
    """``(world, orbit)``: ``shared_worlds.swarm_a_temperature_world()``, built once per session
    (20 000 s tumbling with temperature and magnetorquer effects, 2 nT noise)."""
    from shared_worlds import swarm_a_temperature_world as build

    return build()


# --- a real Yamcs 5.12.8 (issue 45; tests marked ``yamcs``) -------------------------------------


@pytest.fixture(scope="session")
def yamcs_fitted(swarm_a_temperature_world: Any) -> dict[str, Any]:
    """The four methods the Yamcs exports are checked with, fitted on the shared world."""
    from export_worlds import fitted
    from yamcs_real import METHODS

    return {m: fitted(swarm_a_temperature_world, m) for m in METHODS}


@pytest.fixture(scope="session")
def yamcs_suite(yamcs_fitted: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Any:
    """One Yamcs 5.12.8 for the session: instance ``suite`` with docs/yamcs.md's mission MDB and
    one calibration MDB per method × names (and one with telemetered inputs); stopped at the end.
    Yields ``(server, {cell: mdb file}, fitted)``."""
    from yamcs_real import METHODS, YamcsServer, write_suite_folder

    folder = tmp_path_factory.mktemp("yamcs-suite")
    cells = [(m, n) for m in METHODS for n in ("default", "custom", "qualified")]
    cells.append(("linear-hk", "telemetered"))
    documents = {m: f.document for m, f in yamcs_fitted.items()}
    files = write_suite_folder(folder, documents, cells)
    server = YamcsServer(folder)
    try:
        server.start(["suite"])
        yield server, files, yamcs_fitted
    finally:
        server.stop()
