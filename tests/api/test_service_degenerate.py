"""Degenerate data through every HTTP route that reads it (issue 23 item 4, issue 24 item 6).

For each degenerate input (empty upload, one sample, ten samples, a constant field, NaN-free but
singular readings) stored for a spacecraft: upload, retrain (the job's outcome), the calibration
and its history, and the diagnosis. No answer may be a 5xx; a job fails only with a named
library error (never a built-in exception). The table (route × input → outcome) is printed.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import numpy as np
import pandas as pd
import pytest
from service_helpers import LiveServer, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

INPUTS = ("empty", "one sample", "ten samples", "constant field", "singular (dead axis)")
BUILTIN = (
    "ValueError",
    "TypeError",
    "KeyError",
    "IndexError",
    "ZeroDivisionError",
    "LinAlgError",
    "AssertionError",
    "RuntimeError",
    "OverflowError",
    "AttributeError",
)
TABLE: list[tuple[str, str, str]] = []


def _table(name: str) -> pd.DataFrame:
    df, _ = world(T0_UTC_S, 400)
    if name == "empty":
        return df.iloc[:0]
    if name == "one sample":
        return df.iloc[:1]
    if name == "ten samples":
        return df.iloc[:10]
    if name == "constant field":
        for axis in ("b_x", "b_y", "b_z"):
            df[axis] = float(df[axis].iloc[0])
        return df
    df["b_z"] = 1234.5
    return df


@pytest.fixture(scope="module", autouse=True)
def _print_table() -> Iterator[None]:
    yield
    if TABLE:
        print(f"\n{'route':38s} {'input':22s} outcome")
        for route, case, outcome in TABLE:
            print(f"{route:38s} {case:22s} {outcome}")


def _record(route: str, case: str, call: Callable[[], Any], failures: list[str]) -> Any:
    try:
        r = call()
    except httpx.TransportError as exc:  # e.g. the connection dropped after an unhandled error
        TABLE.append((route, case, f"no answer: {type(exc).__name__}"))
        failures.append(f"{route} on {case}: no answer ({exc!r})")
        return None
    detail = ""
    if r.headers.get("content-type", "").startswith("application/json") and r.status_code >= 400:
        detail = " ".join(str(r.json().get("detail", "")).split())[:80]
    TABLE.append((route, case, f"{r.status_code} {detail}".strip()))
    if r.status_code >= 500:
        failures.append(f"{route} on {case}: {r.status_code} {r.text[:200]}")
    return r


@pytest.mark.parametrize("case", INPUTS)
def test_no_route_answers_5xx_on_degenerate_data(server: LiveServer, case: str) -> None:
    sc = "sc-" + case.split()[0]
    failures: list[str] = []
    buf = io.BytesIO()
    _table(case).to_parquet(buf, index=False)
    with server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE}).status_code == 201
        _record(
            "POST telemetry",
            case,
            lambda: c.post(
                f"/v1/spacecraft/{sc}/telemetry",
                content=buf.getvalue(),
                headers={"content-type": "application/vnd.apache.parquet"},
            ),
            failures,
        )
        r = _record(
            "POST calibrations", case, lambda: c.post(f"/v1/spacecraft/{sc}/calibrations"), failures
        )
        assert r is not None, failures
        job = wait_job(c, r.json()["job_id"])
        error = job["error"] or ""
        outcome = job["status"] if not error else f"{job['status']}: {error[:80]}"
        if job["result"]:
            outcome += f" ({job['result']['rule']})"
        TABLE.append(("  job", case, outcome))
        if error.startswith(BUILTIN):
            failures.append(f"job on {case}: {error}")
        _record(
            "GET calibration", case, lambda: c.get(f"/v1/spacecraft/{sc}/calibration"), failures
        )
        _record(
            "GET calibrations", case, lambda: c.get(f"/v1/spacecraft/{sc}/calibrations"), failures
        )
        _record("GET diagnosis", case, lambda: c.get(f"/v1/spacecraft/{sc}/diagnosis"), failures)
        _record("GET metrics", case, lambda: c.get("/metrics"), failures)
    assert failures == []
    if case in ("constant field", "singular (dead axis)"):
        # enough rows to fit: the fit ran and was refused, saying why
        assert job["status"] == "succeeded" and job["result"]["rule"] == "undetermined", job
        assert np.isfinite(job["result"]["identity_rms_nt"])
