"""A catalogue of bad inputs over real HTTP: each gets its expected, clear error, and nothing else
is lost — every upload carries good rows beside the bad ones (or follows good uploads), and at
the end exactly the good samples are stored."""

from __future__ import annotations

import gzip
import os
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import psutil
import pytest
from pydantic import SecretStr
from reliability_helpers import (
    ADMIN_KEY,
    CSV,
    SWARM_A_TLE,
    T0_UTC_S,
    LiveServer,
    live_server,
    physical_csv,
    sqlite_query,
)

from orbitcal import ccsds
from service.settings import Settings

MAX_BODY = 8 * 1024 * 1024  # the test server's body limit [bytes]
HEADER = "time,b_x,b_y,b_z,q_w,q_x,q_y,q_z"


def _tle_line(text: str) -> str:
    """A TLE line with its modulo-10 checksum recomputed (column 69)."""
    total = sum(int(c) if c.isdigit() else (c == "-") for c in text[:68])
    return text[:68] + str(total % 10)


#: Swarm A's elements made to decay: mean motion 16.3 rev/day, B* 5e-3 (SGP4 error 6 days later).
DECAYING_TLE = (
    _tle_line("1 39452U 13067B   22213.51971877  .00500000  00000+0  50000-2 0  999")
    + "\n"
    + _tle_line("2 39452  87.3611 208.4349 0002354 100.1496 260.0021 16.30000000488835")
)


def _row(t: float, b: tuple[float, float, float], q: tuple[float, ...] = (1, 0, 0, 0)) -> str:
    return ",".join(repr(float(v)) for v in (t, *b, *q))


def _good(t0: float, n: int) -> list[str]:
    return [_row(t0 + i, (2e4 + i, -1e4, 3e4)) for i in range(n)]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, Path]]:
    db = tmp_path_factory.mktemp("bad") / "bad.sqlite"
    settings = Settings(
        database_url=f"sqlite:///{db}",
        admin_key=SecretStr(ADMIN_KEY),
        scheduler=False,
        max_body_bytes=MAX_BODY,
        log_level="CRITICAL",
    )
    with live_server(settings) as s:
        with s.client() as http:
            assert http.post("/v1/spacecraft", json={"id": "sat-1"}).status_code == 201
        yield s, db


def _post(
    server: LiveServer, body: Any, headers: dict[str, str], sc: str = "sat-1"
) -> httpx.Response:
    with server.client() as http:
        return http.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers=headers)


def _stored(db: Path) -> int:
    [(n,)] = sqlite_query(
        db,
        "SELECT COUNT(*) FROM samples s JOIN spacecraft c ON c.pk = s.spacecraft_pk "
        "WHERE c.id = 'sat-1'",
    )
    return int(n)


# Row-level problems: the bad rows are named, the good rows of the same upload are kept.
NAN, INF = float("nan"), float("inf")
ROW_CASES: list[tuple[str, Callable[[float], str], str]] = [
    ("NaN field", lambda t: _row(t, (NAN, 1.0, 2.0)), "b_x is missing or not finite"),
    ("infinite field", lambda t: _row(t, (1.0, INF, 2.0)), "b_y is missing or not finite"),
    ("1e12 nT", lambda t: _row(t, (1e12, 0.0, 0.0)), "|b| above 1e+06 nT"),
    ("non-unit quaternion", lambda t: _row(t, (1.0, 2.0, 3.0), (0.9, 0.1, 0, 0)), "not unit"),
    ("NaN quaternion", lambda t: _row(t, (1.0, 2.0, 3.0), (NAN, 0, 0, 1)), "q_w is missing"),
    ("time before 1900", lambda t: _row(-2.3e9, (1.0, 2.0, 3.0)), "time outside 1900–2200"),
    ("unreadable time", lambda t: "yesterday,1,2,3,1,0,0,0", "time"),
    ("text in a number", lambda t: f"{t!r},abc,1,2,1,0,0,0", "b_x is not a number"),
]


@pytest.mark.parametrize(("name", "bad_row", "reason"), ROW_CASES, ids=[c[0] for c in ROW_CASES])
def test_bad_rows_are_named_and_the_good_rows_kept(
    server: tuple[LiveServer, Path], name: str, bad_row: Callable[[float], str], reason: str
) -> None:
    s, db = server
    t0 = T0_UTC_S + 1e5 * (1 + [c[0] for c in ROW_CASES].index(name))
    good = _good(t0, 5)
    before = _stored(db)
    r = _post(s, "\n".join([HEADER, *good[:2], bad_row(t0 + 99), *good[2:]]) + "\n", CSV)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["accepted"] == 5 and body["duplicates"] == 0
    assert [e["row"] for e in body["rejected"]] == [2]
    assert reason in body["rejected"][0]["reason"], body
    assert _stored(db) == before + 5


def test_duplicate_and_unsorted_times(server: tuple[LiveServer, Path]) -> None:
    s, db = server
    t0 = T0_UTC_S + 2e6
    rows = _good(t0, 6)
    shuffled = [rows[i] for i in (4, 1, 5, 0, 3, 2)]
    dup = rows[3].replace("20003.0", "99999.0")  # same time as row 3, other field
    before = _stored(db)
    r = _post(s, "\n".join([HEADER, *shuffled, dup]) + "\n", CSV)
    assert r.status_code == 200
    body = r.json()
    assert body["accepted"] == 6
    assert [e["row"] for e in body["rejected"]] == [6]
    assert "duplicate time" in body["rejected"][0]["reason"]
    assert "(row 4 kept)" in body["rejected"][0]["reason"]
    assert _stored(db) == before + 6
    stored = sqlite_query(
        db,
        "SELECT t_utc_us, b_x FROM samples WHERE t_utc_us >= ? ORDER BY t_utc_us",
        (int(t0 * 1e6),),
    )
    assert [b for _, b in stored] == [2e4 + i for i in range(6)]  # the first of the duplicates
    # The same upload again: all duplicates of stored samples, nothing changes.
    r = _post(s, "\n".join([HEADER, *shuffled]) + "\n", CSV)
    assert r.json() == {"accepted": 0, "duplicates": 6, "rejected": []}


def test_truncated_and_foreign_packets(server: tuple[LiveServer, Path]) -> None:
    s, db = server
    t = T0_UTC_S + 3e6 + np.arange(4.0)
    packets = ccsds.encode_packets(t, np.full((4, 3), 2e4), q_wxyz=np.tile([1.0, 0, 0, 0], (4, 1)))
    foreign = ccsds.encode_packets(t[:1] + 50, np.zeros((1, 3)), apid=0x123)
    body = packets[: 3 * 85] + foreign + packets[3 * 85 : -10]  # 3 good, 1 other APID, 1 truncated
    before = _stored(db)
    with s.client() as http:
        r = http.post(
            f"/v1/spacecraft/sat-1/telemetry?apid={ccsds.DEFAULT_APID}",
            content=body,
            headers={"content-type": "application/vnd.ccsds.space-packet"},
        )
    assert r.status_code == 200, r.text
    assert r.json()["accepted"] == 3
    assert r.json()["rejected"] == [
        {"row": 3, "reason": f"APID {0x123}, expected {ccsds.DEFAULT_APID}"},
        {"row": 4, "reason": "truncated packet: 75 of 85 octets (stream ends)"},
    ]
    assert _stored(db) == before + 3


WHOLE_CASES: list[tuple[str, bytes, dict[str, str], int, str]] = [
    ("garbage CSV", b"\x00\xff\xfe" * 100, CSV, 400, "not a readable CSV"),
    ("no time column", b"b_x,b_y,b_z\n1,2,3\n", CSV, 400, "missing required column 'time'"),
    ("partial quaternion", b"time,b_x,b_y,b_z,q_w\n1e9,1,2,3,1\n", CSV, 400, "partial quaternion"),
    (
        "not Parquet",
        b"PAR1 not really",
        {"content-type": "application/vnd.apache.parquet"},
        400,
        "Parquet",
    ),
    ("JSON object", b'{"time": 1}', {"content-type": "application/json"}, 400, "JSON"),
    ("empty CCSDS", b"", {"content-type": "application/vnd.ccsds.space-packet"}, 400, "empty"),
    ("wrong content type", b"<xml/>", {"content-type": "application/xml"}, 415, "text/csv"),
    ("no content type", b"time,b_x\n", {}, 415, "Content-Type"),
    ("bad gzip", b"not gzip", {**CSV, "content-encoding": "gzip"}, 400, "gzip"),
    ("brotli", b"x", {**CSV, "content-encoding": "br"}, 400, "Content-Encoding"),
    (
        "gzip bomb",
        gzip.compress(b"0" * (64 * MAX_BODY)),
        {**CSV, "content-encoding": "gzip"},
        413,
        "decompressed body exceeds",
    ),
]


@pytest.mark.parametrize(
    ("name", "body", "headers", "status", "says"), WHOLE_CASES, ids=[c[0] for c in WHOLE_CASES]
)
def test_unreadable_uploads_are_refused_whole_and_store_nothing(
    server: tuple[LiveServer, Path],
    name: str,
    body: bytes,
    headers: dict[str, str],
    status: int,
    says: str,
) -> None:
    s, db = server
    before = _stored(db)
    r = _post(s, body, headers)
    assert r.status_code == status, (name, r.text)
    assert says in r.json()["detail"], r.json()
    assert _stored(db) == before


@pytest.mark.parametrize(
    "prefix", [b"null\n", b"\xef\xbb\xbfnull\n", b"\r\n null\nnullx\n"], ids=["null", "bom", "two"]
)
def test_ndjson_starting_with_null_is_a_row_error_not_a_crash(
    server: tuple[LiveServer, Path], prefix: bytes
) -> None:
    # This body used to kill the API process (pyarrow's JSON reader segfaults on it).
    s, db = server
    t0 = T0_UTC_S + 4e6 + 100 * len(prefix)
    lines = [f'{{"time": {t0 + i!r}, "b_x": 1.0, "b_y": 2.0, "b_z": 3.0}}' for i in range(3)]
    n_null = prefix.count(b"null")
    before = _stored(db)
    r = _post(s, prefix + "\n".join(lines).encode(), {"content-type": "application/x-ndjson"})
    assert r.status_code == 200, r.text
    assert r.json()["accepted"] == 3
    assert [e["row"] for e in r.json()["rejected"]] == list(range(n_null))
    assert "JSON" in r.json()["rejected"][0]["reason"]
    assert _stored(db) == before + 3
    # A body with no object at all: every row rejected (422), each with its reason.
    r = _post(s, b"null", {"content-type": "application/x-ndjson"})
    assert r.status_code == 422, r.text
    assert "not a JSON object" in r.json()["detail"]
    assert r.json()["rejected"][0]["row"] == 0
    with s.client() as http:
        assert http.get("/healthz").status_code == 200


def test_unknown_spacecraft_is_404_before_reading_the_body(server: tuple[LiveServer, Path]) -> None:
    s, _ = server
    r = _post(s, "\n".join([HEADER, *_good(T0_UTC_S, 2)]), CSV, sc="nobody")
    assert r.status_code == 404 and "'nobody'" in r.json()["detail"]
    with s.client() as http:
        assert http.get("/v1/spacecraft/nobody/calibration").status_code == 404
        assert http.post("/v1/spacecraft/nobody/calibrations").status_code == 404


def test_1_gb_bodies_are_refused_without_being_held(server: tuple[LiveServer, Path]) -> None:
    s, db = server
    before = _stored(db)
    me = psutil.Process(os.getpid())  # the server runs in this process
    rss0 = me.memory_info().rss
    # Declared 1 GB (raw socket: a client library will not announce bytes it does not send):
    # refused from the header alone.
    host, port = s.url.removeprefix("http://").split(":")
    t0 = time.perf_counter()
    with socket.create_connection((host, int(port)), timeout=30) as sock:
        sock.sendall(
            b"POST /v1/spacecraft/sat-1/telemetry HTTP/1.1\r\nHost: x\r\n"
            b"Content-Type: text/csv\r\nContent-Length: 1000000000\r\n"
            + f"X-API-Key: {ADMIN_KEY}\r\n\r\n".encode()
            + b"time,b_x,b_y,b_z\n"
        )
        answer = sock.recv(65536).decode(errors="replace")
    declared_s = time.perf_counter() - t0
    assert answer.startswith("HTTP/1.1 413"), answer[:200]
    assert "exceeds" in answer
    # Streamed 1 GB without a length (chunked): counted while read, refused at the limit.
    sent = 0

    def gigabyte() -> Iterator[bytes]:
        nonlocal sent
        chunk = b"1,2,3,4\n" * 131072  # 1 MiB
        for _ in range(1024):
            sent += len(chunk)
            yield chunk

    t0 = time.perf_counter()
    with httpx.Client(base_url=s.url, headers={"X-API-Key": ADMIN_KEY}, timeout=120) as http:
        try:
            r = http.post("/v1/spacecraft/sat-1/telemetry", content=gigabyte(), headers=CSV)
            status = r.status_code
        except httpx.TransportError:  # the server may close the connection once it answered
            status = -1
    streamed_s = time.perf_counter() - t0
    grown_mb = (me.memory_info().rss - rss0) / 2**20
    assert status in (413, -1), status
    assert sent < 2**30, "the server read the whole gigabyte"
    assert grown_mb < 4 * MAX_BODY / 2**20 + 64, f"RSS grew {grown_mb:.0f} MB"
    assert _stored(db) == before
    print(
        f"\n1 GB declared: 413 in {declared_s * 1e3:.1f} ms; 1 GB streamed: stopped after "
        f"{sent / 2**20:.0f} MiB in {streamed_s:.2f} s (status {status}), RSS +{grown_mb:.0f} MB"
    )


def test_bad_tle_checksum_is_422_naming_the_field(server: tuple[LiveServer, Path]) -> None:
    s, _ = server
    l1, l2 = SWARM_A_TLE.splitlines()
    with s.client() as http:
        r = http.post("/v1/spacecraft", json={"id": "bad-tle", "tle": l1[:-1] + "1\n" + l2})
        assert r.status_code == 422
        assert "checksum" in r.json()["detail"]
        assert r.json()["errors"][0]["field"] == "tle"
        assert http.get("/v1/spacecraft/bad-tle").status_code == 404  # nothing registered
        r = http.put("/v1/spacecraft/sat-1/orbit", json={"tle": "1 garbage\n2 garbage"})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "tle"


def _retrain_error(http: httpx.Client, sc: str) -> str:
    job_id = http.post(f"/v1/spacecraft/{sc}/calibrations").json()["job_id"]
    deadline = time.monotonic() + 120
    while (job := http.get(f"/v1/jobs/{job_id}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, job
        time.sleep(0.1)
    assert job["status"] == "failed", job
    return str(job["error"])


@pytest.mark.timeout(300)
def test_decayed_tle_and_dates_outside_igrf_fail_the_retraining_clearly(
    server: tuple[LiveServer, Path],
) -> None:
    s, _ = server
    with s.client() as http:
        # Decayed elements: accepted as an orbit (they parse), but SGP4 cannot place the samples.
        assert http.post("/v1/spacecraft", json={"id": "decayed", "tle": DECAYING_TLE}).is_success
        later = T0_UTC_S + 10 * 86400
        r = http.post(
            "/v1/spacecraft/decayed/telemetry",
            content=physical_csv(later, 300).replace(b",r_x,r_y,r_z", b",hk_rx,hk_ry,hk_rz"),
            headers=CSV,
        )
        assert r.json()["accepted"] == 300, r.text
        error = _retrain_error(http, "decayed")
        assert "decay" in error.lower() or "sgp4" in error.lower(), error
        assert http.get("/v1/spacecraft/decayed/calibration").status_code == 404

        # Samples after IGRF-14's span (2030): stored, but no calibration against IGRF-14.
        assert http.post("/v1/spacecraft", json={"id": "future"}).is_success
        t2040 = 2_208_988_800.0  # 2040-01-01T00:00:00Z
        text = physical_csv(T0_UTC_S, 300).decode().splitlines()
        shifted = [text[0]] + [
            f"{float(line.split(',', 1)[0]) + (t2040 - T0_UTC_S)!r},{line.split(',', 1)[1]}"
            for line in text[1:]
        ]
        r = http.post(
            "/v1/spacecraft/future/telemetry", content="\n".join(shifted) + "\n", headers=CSV
        )
        assert r.json()["accepted"] == 300
        error = _retrain_error(http, "future")
        # Either the field model's span is named, or (issue 10 item 7) the rows dated in the
        # future are left out of the window and the job says so.
        assert ("IGRF-14 is valid" in error and "2030" in error) or (
            "300 dated in the future" in error
        ), error
