"""Schemathesis against the service's own ``/openapi.json``: every operation, well-formed and
malformed requests (positive and negative generation), with the admin key, with no key and with
a wrong key. No answer may be a 5xx, and every answer must conform to the schema (documented
status code, content type, headers and body)."""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from pydantic import SecretStr
from reliability_helpers import ADMIN_KEY, CSV, SWARM_A_TLE, T0_UTC_S, LiveServer, csv_batch
from reliability_helpers import live_server as _live_server
from schemathesis import GenerationMode
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from service.settings import Settings

#: Generated cases per operation and generation mode, with the admin key.
CASES_ADMIN = 40
#: ... and with no key / a wrong key (authentication must fail cleanly, never 5xx).
CASES_ANON = 10
MIN_TOTAL_CASES = 1000
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    db: Path = tmp_path_factory.mktemp("fuzz") / "fuzz.sqlite"
    settings = Settings(
        database_url=f"sqlite:///{db}",
        admin_key=SecretStr(ADMIN_KEY),
        scheduler=False,
        log_level="CRITICAL",
    )
    with _live_server(settings) as s:
        with s.client() as http:
            assert http.post("/v1/spacecraft", json={"id": "sat-1", "tle": SWARM_A_TLE}).is_success
            r = http.post(
                "/v1/spacecraft/sat-1/telemetry", content=csv_batch(T0_UTC_S, 50), headers=CSV
            )
            assert r.json()["accepted"] == 50
        yield s


def _run(
    operation: Any,
    url: str,
    mode: GenerationMode,
    headers: dict[str, str],
    n: int,
    seen: Counter[str],
) -> list[str]:
    failures: list[str] = []
    label = f"{operation.method.upper()} {operation.path}"

    @settings(
        max_examples=n,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy(generation_mode=mode))
    def run(case: Any) -> None:
        seen[label] += 1
        try:
            response = case.call(base_url=url, headers=headers, timeout=60)
            case.validate_response(response, checks=CHECKS)
        except (
            Exception,
            BaseExceptionGroup,
        ) as exc:  # collect every operation's failure, report them all
            failures.append(f"{label} [{mode.value}, key={'X-API-Key' in headers}]: {exc}")
            raise

    with contextlib.suppress(Exception, BaseExceptionGroup):
        run()  # a failure is recorded in ``failures`` (the last one is hypothesis's minimal case)
    return failures[-1:]


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_every_operation_survives_generated_requests(server: LiveServer) -> None:
    spec = httpx.get(server.url + "/openapi.json").json()
    schema = schemathesis.openapi.from_dict(spec)
    operations = [r.ok() for r in schema.get_all_operations()]  # type: ignore[union-attr]
    documented = {(m.lower(), p) for p, ops in spec["paths"].items() for m in ops}
    assert {(op.method.lower(), op.path) for op in operations} == documented
    seen: Counter[str] = Counter()
    failures: list[str] = []
    for op in operations:
        for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
            failures += _run(op, server.url, mode, {"X-API-Key": ADMIN_KEY}, CASES_ADMIN, seen)
        failures += _run(op, server.url, GenerationMode.POSITIVE, {}, CASES_ANON, seen)
        failures += _run(
            op, server.url, GenerationMode.POSITIVE, {"X-API-Key": "ock_wrong"}, CASES_ANON, seen
        )
    total = sum(seen.values())
    print(f"\nschemathesis: {total} cases over {len(operations)} operations")
    assert not failures, "\n\n".join(failures)
    assert set(seen) == {f"{op.method.upper()} {op.path}" for op in operations}
    assert total >= MIN_TOTAL_CASES, total
