"""Black-box probes of issue 44's classes 1-5 and 7 against a real ``orbitcal serve``.

* ``names-code``: a telemetry key uploads NDJSON whose housekeeping columns are C/COSMOS/XML
  injections, the spacecraft is retrained with ``linear-hk``; every export of the version in
  service is handed to its consumer: the C header compiled (``cc -Werror``) with its comments
  removed by the compiler holds no injected declaration or directive; the COSMOS fragment has
  exactly three ``ITEM`` lines; every XTCE parameter name is a name.
* ``names-collide``: ``raw_names`` / ``cal_names`` that repeat a coefficient parameter or each
  other's last path element: 422 naming the option.
* ``query-grammar``: percent-encoded ``format``, ``?format`` without ``=`` and ``?format=`` on
  the cached fast path (cache warmed first) and on the routes: the route's answer everywhere.
* ``path-bounds``: versions past 64 bits, ±2^63, 0: 422 (2^63 − 1 is a 404), never a 500.
* ``numbers``: Arabic-Indic digits, ``1_000``, ``+1``, `` 1``, ``1.0`` in ``start`` / ``end`` /
  versions / limits: 422, nothing deleted.
* ``key-revocation``: an upload trickled over a socket while its key is revoked: 401 and
  nothing stored; ``POST /v1/keys`` answers ``Cache-Control: no-store``.
"""

from __future__ import annotations

import io
import json
import re
import shutil
import socket
import subprocess
import tempfile
import time
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import httpx
import numpy as np
import pytest
from probes import RESULTS, Probe, ProbeResult, ServeProcess, serve_process
from reliability_helpers import SWARM_A_TLE, T0_UTC_S, physical_csv

HOSTILE_COLUMNS = (
    'hk_a*/ int ORBITCAL_INJECTED_A; /*"<]]>&',
    "hk_b\n  ITEM ORBITCAL_INJECTED_B 0 0 DERIVED",
    "hk_c\n#error ORBITCAL_INJECTED_C",
)
NAME = re.compile(r"(?:/?[A-Za-z_][A-Za-z0-9_\-]*)+")
CAL = "/v1/spacecraft/{sc}/calibration"
V1 = "/v1/spacecraft/{sc}/calibrations/1"


@dataclass
class World:
    server: ServeProcess
    sc: str  # hostile hk columns, a calibration in service (version 1)
    data_sc: str  # 50 rows, for the deletion probes


def _ndjson(n: int) -> bytes:
    """``physical_csv``'s rows as NDJSON with the hostile housekeeping columns."""
    lines = physical_csv(T0_UTC_S, n).decode().splitlines()
    head = lines[0].split(",")
    rng = np.random.default_rng(44)
    out = []
    for line in lines[1:]:
        row: dict[str, object] = dict(zip(head, map(float, line.split(",")), strict=True))
        for col in HOSTILE_COLUMNS:
            row[col] = float(rng.normal(20.0, 3.0))
        out.append(json.dumps(row))
    return ("\n".join(out) + "\n").encode()


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    env = {"ORBITCAL_READ_CACHE_S": "3600", "ORBITCAL_MIN_SAMPLES": "100"}
    with serve_process(tmp_path_factory.mktemp("probes_exports"), env=env) as server:
        sc = server.new_spacecraft("names", tle=SWARM_A_TLE)
        with server.client() as http:
            r = http.post(
                f"/v1/spacecraft/{sc}/telemetry",
                content=_ndjson(600),
                headers={"content-type": "application/x-ndjson"},
            )
            assert r.status_code == 200, r.text
            job = http.post(f"/v1/spacecraft/{sc}/calibrations", json={"method": "linear-hk"})
            assert job.status_code == 202, job.text
            job_id = job.json()["job_id"]
            deadline = time.monotonic() + 300
            while True:
                state = http.get(f"/v1/jobs/{job_id}").json()
                if state["status"] in ("succeeded", "failed") or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert state["status"] == "succeeded", state
            assert http.get(f"/v1/spacecraft/{sc}/calibration").status_code == 200
        data_sc = server.new_spacecraft("numbers")
        with server.client() as http:
            r = http.post(
                f"/v1/spacecraft/{data_sc}/telemetry",
                content=physical_csv(T0_UTC_S, 50),
                headers={"content-type": "text/csv"},
            )
            assert r.status_code == 200, r.text
        yield World(server, sc, data_sc)


def _warm(world: World) -> None:
    """Fill the read cache so that ``GET …/calibration`` may take the fast path."""
    with world.server.client() as http:
        assert http.get(CAL.format(sc=world.sc)).status_code == 200


# ------------------------------------------------------------------ class 1: names become code


def _c_code(header: bytes) -> str:
    cc = shutil.which("cc")
    assert cc is not None
    with tempfile.TemporaryDirectory() as tmp:
        h = Path(tmp) / "orbitcal_magcal.h"
        h.write_bytes(header)
        (Path(tmp) / "main.c").write_text(
            '#include "orbitcal_magcal.h"\nint main(void){return 0;}\n'
        )
        build = subprocess.run(
            [cc, "-std=c99", "-Wall", "-Werror", "-pedantic", "-fsyntax-only", "main.c"],
            cwd=tmp,
            capture_output=True,
        )
        assert build.returncode == 0, build.stderr.decode(errors="replace")[:1000]
        return subprocess.run(
            [cc, "-fpreprocessed", "-dD", "-E", "-P", str(h)], capture_output=True, check=True
        ).stdout.decode("latin-1")


def _check_c(_s: ServeProcess, _sc: str, r: httpx.Response) -> None:
    code = _c_code(r.content)
    assert "ORBITCAL_INJECTED" not in code, "a column name became C code"
    assert "#error" not in code


def _check_cosmos(_s: ServeProcess, _sc: str, r: httpx.Response) -> None:
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        tlm = z.read("targets/MAGCAL/cmd_tlm/magcal_tlm.txt").decode()
        plugin = z.read("plugin.txt").decode()
    items = [ln for ln in tlm.splitlines() if ln.strip().startswith("ITEM")]
    assert len(items) == 3, items
    keywords = {"ITEM", "UNITS", "READ_CONVERSION", "SELECT_TELEMETRY", "VARIABLE"}
    for text in (tlm, plugin):
        for ln in text.splitlines():
            if ln.lstrip().startswith("#") or not ln.strip():
                # a comment cannot open an ERB tag of its own
                assert ln.isascii() and ln.count("<%") == ln.count("<%= magcal_"), ln
                continue
            assert ln.split()[0] in keywords, ln
            assert ln.count("<%") == ln.count("<%= magcal_"), ln


def _check_xtce(_s: ServeProcess, _sc: str, r: httpx.Response) -> None:
    import xml.etree.ElementTree as ET

    root = ET.fromstring(r.content)
    ns = "{http://www.omg.org/spec/XTCE/20180204}"
    names = [p.get("name", "") for p in root.iter(ns + "Parameter")]
    assert names and len(names) == len(set(names))
    bad = [n for n in names if not NAME.fullmatch(n)]
    assert not bad, bad
    text = root.findtext(f".//{ns}AlgorithmText") or ""
    assert all(ln.isascii() for ln in text.splitlines())


def _get(name: str, klass: str, path: str, status: int | tuple[int, ...], **kw: object) -> Probe:
    return Probe(name=name, klass=klass, method="GET", path=path, status=status, stored=None, **kw)  # type: ignore[arg-type]


NAME_PROBES = [
    _get("c-header-in-service", "names-code", CAL + "?format=c-header", 200, check=_check_c),
    _get("c-header-version-1", "names-code", V1 + "?format=c-header", 200, check=_check_c),
    _get("cosmos-in-service", "names-code", CAL + "?format=cosmos", 200, check=_check_cosmos),
    _get("xtce-in-service", "names-code", CAL + "?format=xtce", 200, check=_check_xtce),
    _get(
        "c-header-renamed-hk",
        "names-code",
        CAL + "?format=c-header&hk_names=" + quote(HOSTILE_COLUMNS[0], safe="") + "=HK_A",
        (200, 422),
        check=lambda s, sc, r: _check_c(s, sc, r) if r.status_code == 200 else None,
    ),
    _get(
        "xtce-raw-name-newline",
        "names-code",
        CAL + "?format=xtce&raw_names=A%0AB,C,D",
        422,
        says=("raw_names",),
    ),
    _get(
        "cosmos-cal-name-erb",
        "names-code",
        CAL + "?format=cosmos&cal_names=%3C%25%3D%60id%60%25%3E,B,C",
        422,
        says=("cal_names",),
    ),
    _get(
        "cosmos-cal-name-double-underscore",
        "names-code",
        CAL + "?format=cosmos&cal_names=A__B,C,D",
        422,
        says=("cal_names",),
    ),
    # class 2: names checked against each other and the export's own
    _get(
        "xtce-raw-is-coefficient",
        "names-collide",
        CAL + "?format=xtce&raw_names=MAGCAL_M_0_0,MAGCAL_M_0_1,MAGCAL_M_0_2",
        422,
        says=("named twice",),
    ),
    _get(
        "yamcs-push-raw-is-coefficient",
        "names-collide",
        CAL + "?format=yamcs-push&raw_names=MAGCAL_O_0,B,C",
        422,
        says=("named twice",),
    ),
    _get(
        "cosmos-raw-same-item",
        "names-collide",
        CAL + "?format=cosmos&raw_names=/A/X,/B/X,/C/X",
        422,
        says=("named twice",),
    ),
    _get(
        "xtce-cal-same-lin",
        "names-collide",
        V1 + "?format=xtce&cal_names=/A/Q,/B/Q,/C/Q",
        422,
        says=("named twice",),
    ),
    _get(
        "cosmos-case-twins",
        "names-collide",
        V1 + "?format=cosmos&raw_names=a,b,c&cal_names=A,B,C",
        422,
        says=("named twice",),
    ),
    _get(
        "c-header-hk-is-raw",
        "names-collide",
        CAL + "?format=c-header&hk_names=" + quote(HOSTILE_COLUMNS[0], safe="") + "=MAG_X_RAW",
        422,
        says=("named twice",),
    ),
]


@pytest.mark.slow
@pytest.mark.parametrize("probe", NAME_PROBES, ids=lambda p: p.name)
def test_names(world: World, probe: Probe) -> None:
    world.server.run(Probe(**{**probe.__dict__, "spacecraft": world.sc}))


# ------------------------------------------------------------------ class 3: one query grammar

_TYPES = {"xtce": "application/xml", "c-header": "text/x-c"}
QUERY_PROBES = [
    _get("pct-format-xtce", "query-grammar", CAL + "?%66ormat=xtce", 200),
    _get("pct-format-c-header", "query-grammar", CAL + "?f%6Frmat=c-header", 200),
    _get("format-without-equals", "query-grammar", CAL + "?format", 422),
    _get("format-empty-in-service", "query-grammar", CAL + "?format=", 422),
    _get("format-empty-version", "query-grammar", V1 + "?format=", 422),
    _get("format-without-equals-version", "query-grammar", V1 + "?format", 422),
]


@pytest.mark.slow
@pytest.mark.parametrize("probe", QUERY_PROBES, ids=lambda p: p.name)
def test_query_grammar(world: World, probe: Probe) -> None:
    _warm(world)

    def same_type(_s: ServeProcess, _sc: str, r: httpx.Response) -> None:
        for fmt, media in _TYPES.items():
            if probe.name.endswith(fmt):
                assert r.headers["content-type"].startswith(media), r.headers["content-type"]

    world.server.run(Probe(**{**probe.__dict__, "spacecraft": world.sc, "check": same_type}))


# ------------------------------------------------------------------ classes 4 and 5: numbers

_VERSIONS = {
    "past-64-bits": ("99999999999999999999", 422),
    "2^63": (str(2**63), 422),
    "-2^63": (str(-(2**63)), 422),
    "-2^63-1": (str(-(2**63) - 1), 422),
    "zero": ("0", 422),
    "2^63-1": (str(2**63 - 1), 404),
}
BOUND_PROBES = [
    _get(f"version-{k}", "path-bounds", "/v1/spacecraft/{sc}/calibrations/" + v, s)
    for k, (v, s) in _VERSIONS.items()
]
_HOSTILE_NUMBERS = {
    "arabic-indic": "%D9%A1%D9%A2",
    "underscore": "1_000",
    "plus": "%2B1",
    "space": "%201",
    "fullwidth": "%EF%BC%91",
}
NUMBER_PROBES = [
    *(
        Probe(
            name=f"delete-start-{k}",
            klass="numbers",
            method="DELETE",
            path="/v1/spacecraft/{sc}/telemetry?start=" + v + "&end=99999999999",
            status=422,
            says=("start",),
            stored=0,
        )
        for k, v in _HOSTILE_NUMBERS.items()
    ),
    *(
        _get(f"version-{k}", "numbers", "/v1/spacecraft/{sc}/calibrations/" + v, 422)
        for k, v in {**_HOSTILE_NUMBERS, "decimal-point": "1.0", "underscore": "1_0"}.items()
    ),
    *(
        _get(f"audit-limit-{k}", "numbers", "/v1/spacecraft/{sc}/data-audit?limit=" + v, 422)
        for k, v in {**_HOSTILE_NUMBERS, "underscore": "1_0"}.items()
    ),
]


@pytest.mark.slow
@pytest.mark.parametrize("probe", BOUND_PROBES + NUMBER_PROBES, ids=lambda p: p.name)
def test_numbers(world: World, probe: Probe) -> None:
    sc = world.data_sc if probe.klass == "numbers" else world.sc
    world.server.run(Probe(**{**probe.__dict__, "spacecraft": sc}))


# ------------------------------------------------------------------ class 7: keys


def _record(
    server: ServeProcess, name: str, status: int, detail: str, stored: int, t: float
) -> ProbeResult:
    result = ProbeResult(
        name=name,
        klass="key-revocation",
        database=server.database,
        status=status,
        detail=detail[:500],
        stored=stored,
        body_bytes=0,
        rss_before_mb=server.rss_mb(),
        peak_rss_mb=server.peak_rss_mb(),
        seconds=t,
        alive=server.alive() and server.healthy(),
    )
    RESULTS.append(result)
    return result


@pytest.mark.slow
def test_new_key_is_not_stored_by_caches(world: World) -> None:
    t0 = time.perf_counter()
    with world.server.client() as http:
        r = http.post("/v1/keys", json={"name": "probe", "scopes": ["read:*"]})
    result = _record(
        world.server,
        "new-key-no-store",
        r.status_code,
        r.headers.get("cache-control", "(none)"),
        0,
        time.perf_counter() - t0,
    )
    try:
        assert r.status_code == 201 and "key" in r.json()
        assert "no-store" in r.headers.get("cache-control", ""), dict(r.headers)
    except AssertionError as exc:
        result.failure = str(exc)[:500]
        raise


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.services)])
def any_server(
    request: pytest.FixtureRequest, world: World, tmp_path: Path
) -> Iterator[ServeProcess]:
    """The module's SQLite server, or a fresh one on PostgreSQL (its row lock ``FOR SHARE``)."""
    if request.param == "sqlite":
        yield world.server
        return
    with serve_process(tmp_path, database="postgresql") as server:
        yield server


@pytest.mark.slow
def test_key_revoked_during_a_trickled_upload(any_server: ServeProcess) -> None:
    server = any_server
    sc = server.new_spacecraft("revoke")
    with server.client() as http:
        made = http.post("/v1/keys", json={"name": "ingest", "scopes": [f"ingest:{sc}"]}).json()
    body = physical_csv(T0_UTC_S + 10_000, 50)
    host, port = server.url.removeprefix("http://").split(":")
    t0 = time.perf_counter()
    with socket.create_connection((host, int(port)), timeout=60) as s:
        s.sendall(
            f"POST /v1/spacecraft/{sc}/telemetry HTTP/1.1\r\nHost: x\r\n"
            f"X-API-Key: {made['key']}\r\n"
            f"Content-Type: text/csv\r\nContent-Length: {len(body)}\r\n\r\n".encode()
        )
        half = len(body) // 2
        s.sendall(body[:half])
        time.sleep(0.5)  # the key has been checked (the route awaits the body)
        with server.client() as http:
            gone = http.delete(f"/v1/keys/{made['prefix']}")
        assert gone.status_code == 204
        time.sleep(0.5)
        s.sendall(body[half:])
        answer = b""
        while b"\r\n\r\n" not in answer or len(answer) < 12:
            chunk = s.recv(65536)
            if not chunk:
                break
            answer += chunk
    status = int(answer[9:12]) if answer.startswith(b"HTTP/1.1 ") else -1
    stored = server.stored_count(sc)
    result = _record(
        server,
        "upload-across-revocation",
        status,
        answer.decode(errors="replace"),
        stored,
        time.perf_counter() - t0,
    )
    try:
        assert status in (401, 403), answer[:300]
        assert stored == 0, f"{stored} rows stored with a revoked key"
    except AssertionError as exc:
        result.failure = str(exc)[:500]
        raise
