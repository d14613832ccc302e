"""One query grammar and one number grammar over the whole service (issue 44, classes 3-5, 7).

* The cached fast path of ``GET …/calibration`` (``CalibrationFastPath``) and the routes
  (``/calibration`` with a cold cache, ``/calibrations/{v}``) answer the same query set with the
  same status, media type and body.
* Every numeric query or path parameter of the OpenAPI document, spelt in hostile ways (other
  scripts' digits, ``_``, ``+``, spaces, ``1.0`` for an integer, ``inf``): 422 naming it, and
  the deletion deletes nothing; versions past 64 bits: 422, 2^63 − 1: 404.
* ``POST /v1/keys`` answers ``Cache-Control: no-store``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from urllib.parse import quote

import httpx
import pytest
from service_helpers import LiveServer, live_server, sqlite_settings, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world


@dataclass
class Served:
    server: LiveServer
    n_rows: int


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    settings = sqlite_settings(tmp_path_factory.mktemp("query_grammar"), read_cache_s=3600.0)
    with live_server(settings) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "sat", "tle": SWARM_A_TLE}).status_code == 201
        df, _ = world(T0_UTC_S, 600)
        r = c.post(
            "/v1/spacecraft/sat/telemetry",
            content=df.to_csv(index=False).encode(),
            headers={"content-type": "text/csv"},
        )
        assert r.status_code == 200, r.text
        job = wait_job(c, c.post("/v1/spacecraft/sat/calibrations").json()["job_id"])
        assert job["status"] == "succeeded", job
        yield Served(server, len(df))


# ------------------------------------------------------------------ fast path == routes

QUERIES = [
    "",
    "?format=json",
    "?format=xtce",
    "?format=c-header",
    "?%66ormat=xtce",
    "?f%6Frmat=c-header",
    "?format",
    "?format=",
    "?format=%20xtce",
    "?format=xtce%00",
    "?format=yaml",
    "?FORMAT=xtce",
    "?format=xtce&format=c-header",
    "?raw_names=A,B,C",
    "?format=xtce&raw_names=A%0AB,C,D",
    "?format=cosmos&raw_names=/A/X,/B/X,/C/X",
    "?&&format=polynomial&",
    "?format=json;x=1",
]


def _answer(r: httpx.Response) -> tuple[int, str, object]:
    media = r.headers.get("content-type", "").split(";")[0]
    body: object = r.content
    if media == "application/json":
        body = json.loads(r.content)
    return r.status_code, media, body


@pytest.mark.parametrize("query", QUERIES)
def test_fast_path_and_routes_read_one_query_grammar(served: Served, query: str) -> None:
    app = served.server.app
    with served.server.client() as c:
        assert c.get("/v1/spacecraft/sat/calibration").status_code == 200  # cache warm
        fast = c.get("/v1/spacecraft/sat/calibration" + query)
        app.state.calibration_cache.clear()  # the route answers and refills the cache
        route = c.get("/v1/spacecraft/sat/calibration" + query)
        version = c.get("/v1/spacecraft/sat/calibrations/1" + query)
    assert fast.status_code < 500 and fast.status_code in (200, 422)
    assert _answer(fast) == _answer(route), query
    f_status, f_media, f_body = _answer(fast)
    v_status, v_media, v_body = _answer(version)
    assert (f_status, f_media) == (v_status, v_media), query
    if f_status == 200:
        assert f_body == v_body, query  # the document, or the same export bytes
    else:
        assert isinstance(f_body, dict) and isinstance(v_body, dict)
        assert f_body["detail"] == v_body["detail"], query


# ------------------------------------------------------------------ numbers

#: Every numeric parameter of the service (checked against the OpenAPI document below):
#: (method, path template, parameter, kind). ``start`` / ``end`` are times: ISO-8601 or Unix
#: seconds in the real-number grammar.
NUMERIC = [
    ("POST", "/v1/spacecraft/sat/telemetry?apid={v}", "apid", "int"),
    ("DELETE", "/v1/spacecraft/sat/telemetry?start={v}&end=99999999999", "start", "real"),
    ("DELETE", "/v1/spacecraft/sat/telemetry?start=0&end={v}", "end", "real"),
    ("DELETE", "/v1/spacecraft/sat/quarantines/{v}", "quarantine_id", "int"),
    ("GET", "/v1/spacecraft/sat/data-audit?limit={v}", "limit", "int"),
    ("GET", "/v1/spacecraft/sat/residuals?max_points={v}", "max_points", "int"),
    ("GET", "/v1/spacecraft/sat/activity?max_jobs={v}", "max_jobs", "int"),
    ("GET", "/v1/spacecraft/sat/calibrations/{v}", "version", "int"),
]
#: Spellings that are not a number in ASCII decimals.
HOSTILE = {
    "arabic-indic": "١٢",
    "fullwidth": "１２",
    "devanagari": "१२",
    "underscore": "1_0",
    "plus": "+12",
    "leading-space": " 12",
    "trailing-space": "12 ",
    "tab": "12\t",
    "newline": "12\n",
    "hex": "0x12",
    "empty": "",
    "inf": "inf",
    "nan": "nan",
}
HOSTILE_INT = {**HOSTILE, "decimal-point": "12.0", "exponent": "1e1", "past-64-bits": "9" * 25}


def test_every_numeric_parameter_is_listed(served: Served) -> None:
    spec = served.server.app.openapi()
    found = set()
    for ops in spec["paths"].values():
        for op in ops.values():
            for p in op.get("parameters", []):
                schema = json.dumps(p["schema"])
                if '"integer"' in schema or '"number"' in schema or p["name"] in ("start", "end"):
                    found.add(p["name"])
    assert found == {name for _, _, name, _ in NUMERIC}


@pytest.mark.parametrize(
    ("method", "path", "name", "spelling"),
    [
        pytest.param(m, p, n, s, id=f"{n}-{k}")
        for m, p, n, kind in NUMERIC
        for k, s in (HOSTILE_INT if kind == "int" else HOSTILE).items()
        if not (k == "empty" and p.endswith("/{v}"))  # an empty path segment is another URL
    ],
)
def test_hostile_numbers_are_refused(
    served: Served, method: str, path: str, name: str, spelling: str
) -> None:
    url = path.format(v=quote(spelling, safe=""))
    with served.server.client() as c:
        r = c.request(
            method,
            url,
            content=b"time,b_x,b_y,b_z\n0,1,2,3\n" if method == "POST" else None,
            headers={"content-type": "text/csv"} if method == "POST" else None,
        )
        rows = c.get("/v1/spacecraft/sat/data-audit").status_code
    assert r.status_code == 422, (url, r.status_code, r.text[:300])
    assert name in r.text
    assert rows == 200
    store = served.server.app.state.engine
    import sqlalchemy as sa

    with store.connect() as conn:
        n = conn.execute(sa.text("SELECT COUNT(*) FROM samples")).scalar_one()
    assert n == served.n_rows, "a hostile number deleted or stored rows"


@pytest.mark.parametrize(
    ("version", "status"),
    [(str(2**63 - 1), 404), (str(2**63), 422), (str(-(2**63)), 422), ("0", 422), ("7", 404)],
)
def test_versions_are_bounded(served: Served, version: str, status: int) -> None:
    with served.server.client() as c:
        r = c.get(f"/v1/spacecraft/sat/calibrations/{version}?format=xtce")
    assert r.status_code == status, r.text[:300]


def test_good_numbers_still_read(served: Served) -> None:
    with served.server.client() as c:
        assert c.get("/v1/spacecraft/sat/calibrations/01").status_code == 200
        assert c.get("/v1/spacecraft/sat/data-audit?limit=10").status_code == 200
        r = c.delete("/v1/spacecraft/sat/telemetry?start=1e1&end=-0.5e1")
    assert r.status_code == 422 and "ends before it starts" in r.text  # read as 10 and -5


def test_new_key_answer_is_not_stored(served: Served) -> None:
    with served.server.client() as c:
        r = c.post("/v1/keys", json={"name": "k", "scopes": ["read:*"]})
    assert r.status_code == 201 and r.json()["key"]
    assert r.headers["cache-control"] == "no-store"
