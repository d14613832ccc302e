"""Inputs that parse but are not physical, through HTTP (issue 44 item 9).

The service's world (``service_worlds.world``, elements of Swarm A, no positions in the table) in
nT, in Tesla, Gauss and µT, with two axes swapped, with one axis stuck, and registered with the
elements of another spacecraft (the ISS set nearest in epoch): the upload's answer, the
retraining job's outcome and whether a calibration is in service afterwards. A table in another
unit is refused at the upload (422 naming the unit and the factor); the others are stored and
their retraining puts nothing in service, saying why. The table is printed (``pytest -s``) and
copied in ``benchmarks/results/degenerate_inputs.md``.
"""

from __future__ import annotations

import io
from collections.abc import Iterator

import httpx
import pytest
from plausibility_cases import CASES, SAYS, case_field
from service_helpers import LiveServer, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

import orbitcal
from orbitcal.data import real_tles_text

B_COLUMNS = ["b_x", "b_y", "b_z"]
TABLE: list[tuple[str, str, str]] = []


@pytest.fixture(scope="module", autouse=True)
def _print_table() -> Iterator[None]:
    yield
    if TABLE:
        print(f"\n{'route':24s} {'input':18s} outcome")
        for route, case, outcome in TABLE:
            print(f"{route:24s} {case:18s} {outcome}")


def _iss_tle() -> str:
    iss = orbitcal.load_orbit(real_tles_text(), norad_id=25544, near_utc_s=T0_UTC_S)
    return "\n".join(iss.source[-2:])


def _body(case: str) -> bytes:
    df, _ = world(T0_UTC_S, 1500, positions=False)
    df[B_COLUMNS] = case_field(df[B_COLUMNS].to_numpy(), case)
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return buf.getvalue()


def _detail(r: httpx.Response) -> str:
    return " ".join(str(r.json().get("detail", "")).split())


@pytest.mark.parametrize("case", CASES)
def test_nothing_implausible_is_stored_as_a_calibration(server: LiveServer, case: str) -> None:
    sc = f"sc-{CASES.index(case)}"
    tle = _iss_tle() if case == "wrong spacecraft" else SWARM_A_TLE
    with server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": sc, "tle": tle}).status_code == 201
        r = c.post(
            f"/v1/spacecraft/{sc}/telemetry",
            content=_body(case),
            headers={"content-type": "application/vnd.apache.parquet"},
        )
        detail = _detail(r) if r.status_code != 200 else f"accepted {r.json()['accepted']}"
        TABLE.append(("POST telemetry", case, f"{r.status_code} {detail}"[:200]))
        if case in ("Tesla", "Gauss", "µT"):
            assert r.status_code == 422 and SAYS[case] in detail, detail
            assert c.get(f"/v1/spacecraft/{sc}/calibration").status_code == 404
            return
        assert r.status_code == 200, r.text
        job = wait_job(c, c.post(f"/v1/spacecraft/{sc}/calibrations").json()["job_id"])
        result = job.get("result") or {}
        outcome = job["status"] + (f": {job['error']}" if job.get("error") else "")
        if result:
            promoted = "promoted" if result.get("promoted") else "not promoted"
            outcome += f" ({promoted}, {result.get('rule')}): {result.get('reason', '')}"
        TABLE.append(("  retraining job", case, " ".join(outcome.split())[:200]))
        served = c.get(f"/v1/spacecraft/{sc}/calibration")
        TABLE.append(("GET calibration", case, str(served.status_code)))
        if case == "nT (control)":
            assert result.get("promoted") and served.status_code == 200, job
            return
        assert not result.get("promoted") and served.status_code == 404, job
        assert SAYS[case] in outcome, outcome


def test_a_small_upload_in_another_unit_is_stored_with_a_warning(server: LiveServer) -> None:
    """Below ``PLAUSIBILITY_MIN_ROWS`` valid rows the unit is not refused, only named."""
    from service.ingest import PLAUSIBILITY_MIN_ROWS

    df, _ = world(T0_UTC_S, PLAUSIBILITY_MIN_ROWS - 1, positions=False)
    df[B_COLUMNS] = case_field(df[B_COLUMNS].to_numpy(), "Tesla")
    with server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "few", "tle": SWARM_A_TLE}).status_code == 201
        r = c.post(
            "/v1/spacecraft/few/telemetry",
            content=df.to_csv(index=False),
            headers={"content-type": "text/csv"},
        )
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["accepted"] == PLAUSIBILITY_MIN_ROWS - 1
    assert "looks like Tesla: scale by 1e9" in body["warnings"][0], body
