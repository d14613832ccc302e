"""Black-box probes against a real ``orbitcal serve`` process: no data poisons a spacecraft.

Rows far in the future or the past, rows without quaternions, all-NaN housekeeping and a single odd
row among thousands must not block retraining (the window is chosen robustly and the job result
says which rows were left out, and why); operators quarantine, release and delete samples by time
range (scoped, audited, counted). Each probe asserts the HTTP status, the message and the state
stored afterwards (read straight from the database), and that the server process is still alive.
The same probes run on SQLite and (marked ``services``) on PostgreSQL.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
import sqlalchemy as sa
from probes import ServeProcess, serve_process
from reliability_helpers import ADMIN_KEY, CSV, SWARM_A_TLE, T0_UTC_S, physical_csv

N = 600  # samples of a base upload: 100 min at 0.1 Hz
DT_S = 10.0
Q_COLUMNS = (4, 5, 6, 7)  # q_w..q_z in physical_csv's header


@functools.cache
def base_csv(n: int = N, seed: int = 0) -> bytes:
    return physical_csv(T0_UTC_S, n, dt_s=DT_S, seed=seed)


def _lines(body: bytes) -> list[str]:
    return body.decode().strip().split("\n")


def _csv(lines: list[str]) -> bytes:
    return ("\n".join(lines) + "\n").encode()


def _row_at(t_s: float) -> str:
    """A valid row (the first base row's values) dated ``t_s``."""
    first = _lines(base_csv())[1].split(",")
    return ",".join([f"{t_s:.6f}", *first[1:]])


def _drop_q(line: str) -> str:
    return ",".join(c for i, c in enumerate(line.split(",")) if i not in Q_COLUMNS)


def _split_attitude(lines: list[str], rows: list[int]) -> tuple[list[str], list[str]]:
    """``lines`` as two tables: the rows ``rows`` without the quaternion columns (a second
    upload, as from a spacecraft whose attitude was not downlinked), and the others."""
    picked = set(rows)
    with_q = [lines[0]] + [x for i, x in enumerate(lines) if i and i not in picked]
    without = [_drop_q(lines[0])] + [_drop_q(lines[i]) for i in rows]
    return with_q, without


class Backend:
    """A real ``orbitcal serve`` process (``probes.serve_process``) and its database."""

    def __init__(self, server: ServeProcess) -> None:
        self.server = server
        self.proc = server.proc
        self.url = server.url

    def client(self, key: str | None = ADMIN_KEY) -> httpx.Client:
        return self.server.client(key)

    def sql(self, text: str, **params: Any) -> Any:
        with self.server.engine.connect() as conn:
            return conn.execute(sa.text(text), params).scalar_one()

    def stored(self, sc: str) -> int:
        return self.server.stored_count(sc)

    def revision(self, sc: str) -> int:
        return int(self.sql("SELECT data_revision FROM spacecraft WHERE id = :sc", sc=sc))

    def quarantines(self, sc: str) -> int:
        return int(
            self.sql(
                "SELECT COUNT(*) FROM quarantines q JOIN spacecraft c ON c.pk = q.spacecraft_pk "
                "WHERE c.id = :sc",
                sc=sc,
            )
        )


@pytest.fixture(
    scope="module",
    params=["sqlite", pytest.param("postgresql", marks=pytest.mark.services)],
)
def backend(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Backend]:
    with serve_process(tmp_path_factory.mktemp("poison"), database=request.param) as server:
        yield Backend(server)


@pytest.fixture(autouse=True)
def _server_survives(backend: Backend) -> Iterator[None]:
    yield
    assert backend.proc.poll() is None, "the server process died"
    assert httpx.get(backend.url + "/healthz", timeout=10).status_code == 200


_COUNTER = iter(range(10**6))


def _new_spacecraft(c: httpx.Client, *tables: list[str]) -> str:
    """Register a spacecraft (Swarm A's TLE) and upload ``tables`` (default: the base table)."""
    sc = f"sat-{next(_COUNTER)}"
    r = c.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE})
    assert r.status_code == 201, r.text
    for body in [_csv(t) for t in tables] or [base_csv()]:
        r = c.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers=CSV)
        assert r.status_code == 200, r.text
        assert r.json()["rejected"] == [], r.text
    return sc


def _retrain(c: httpx.Client, sc: str, **body: Any) -> dict[str, Any]:
    r = c.post(f"/v1/spacecraft/{sc}/calibrations", json=body or None)
    assert r.status_code == 202, r.text
    job_id = r.json()["job_id"]
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        job = c.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in ("succeeded", "failed"):
            return job  # type: ignore[no-any-return]
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} did not finish")


def _succeeded(job: dict[str, Any]) -> dict[str, Any]:
    assert job["status"] == "succeeded", job
    return job["result"]  # type: ignore[no-any-return]


# ---------------------------------------------------------------------------------------------
# Rows that used to poison every later retraining


def test_a_valid_row_dated_2149_does_not_define_the_window(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c, [*_lines(base_csv()), _row_at(5_600_000_000.0)])  # 2147-06
        assert backend.stored(sc) == N + 1
        result = _succeeded(_retrain(c, sc))
    assert result["promoted"] and result["rule"] == "first calibration"
    assert result["rows"]["used"] == N
    assert result["rows"]["excluded"] == {"future": 1}
    assert result["rows"]["reasons"]["future"] == "dated in the future"
    assert result["holdout_rms_nt"] < 5.0  # 2 nT sensor noise
    assert backend.stored(sc) == N + 1  # excluded, not deleted


def test_a_valid_row_dated_1950_stays_outside_the_window(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(
            c, [_lines(base_csv())[0], _row_at(-631_152_000.0), *_lines(base_csv())[1:]]
        )
        result = _succeeded(_retrain(c, sc))
        doc = c.get(f"/v1/spacecraft/{sc}/calibration").json()
    assert result["rows"]["used"] == N and result["rows"]["excluded"] == {}
    assert doc["data"]["n"] == N and doc["data"]["start"].startswith("2022-08-01")
    assert backend.stored(sc) == N + 1


def test_a_lone_row_a_month_after_the_rest_is_left_out_and_counted(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c, [*_lines(base_csv()), _row_at(T0_UTC_S + 30 * 86400.0)])
        result = _succeeded(_retrain(c, sc))
    assert result["rows"]["used"] == N
    assert result["rows"]["excluded"] == {"after_window": 1}
    assert "isolated" in result["rows"]["reasons"]["after_window"]


def test_rows_without_quaternions_are_left_out_of_a_vector_fit_and_counted(
    backend: Backend,
) -> None:
    blank = list(range(1, N + 1, 7))  # every 7th row has no attitude
    with backend.client() as c:
        sc = _new_spacecraft(c, *_split_attitude(_lines(base_csv()), blank))
        assert backend.stored(sc) == N
        result = _succeeded(_retrain(c, sc, method="linear"))
    assert result["rows"]["excluded"] == {"no_attitude": len(blank)}
    assert result["rows"]["used"] == N - len(blank)
    assert result["method"] == "linear" and result["metric"] == "rms_nt"
    assert result["holdout_rms_nt"] < 5.0


def test_one_row_without_quaternions_among_thousands_does_not_block_retraining(
    backend: Backend,
) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c, *_split_attitude(_lines(base_csv(3000, 1)), [1500]))
        first = _succeeded(_retrain(c, sc))
        # the next retraining of the same spacecraft is not blocked either
        second = _succeeded(_retrain(c, sc))
    assert first["rows"]["excluded"] == {"no_attitude": 1} and first["rows"]["used"] == 2999
    assert second["rows"]["excluded"] == {"no_attitude": 1}


def test_without_any_quaternion_a_vector_retraining_fails_saying_why(backend: Backend) -> None:
    lines = [_drop_q(x) for x in _lines(base_csv())]
    with backend.client() as c:
        sc = _new_spacecraft(c, lines)
        job = _retrain(c, sc, method="linear")
        served = c.get(f"/v1/spacecraft/{sc}/calibration")
    assert job["status"] == "failed"
    assert job["error"].startswith("NotEnoughDataError: only 0 usable samples")
    assert f"left out: {N} without attitude (q_w..q_z) for a vector method" in job["error"]
    assert served.status_code == 404
    assert backend.stored(sc) == N


def test_housekeeping_missing_on_most_rows_does_not_block_retraining(backend: Backend) -> None:
    """A channel that only the latest 100 rows carry (NaN on the 600 before it) is left out of
    the fit instead of emptying it."""
    lines = _lines(base_csv(N + 100, 3))
    later = [lines[0] + ",hk_heater"] + [
        x + f",{0.5 + 0.001 * i}" for i, x in enumerate(lines[N + 1 :])
    ]
    with backend.client() as c:
        sc = _new_spacecraft(c, lines[: N + 1], later)
        result = _succeeded(_retrain(c, sc, method="linear-hk"))
        doc = c.get(f"/v1/spacecraft/{sc}/calibration").json()
    assert result["rows"]["used"] == N + 100 and result["promoted"]
    assert "hk_heater" not in str(doc["model"])
    assert backend.stored(sc) == N + 100


def test_an_all_nan_housekeeping_column_is_refused_row_by_row_and_stores_nothing(
    backend: Backend,
) -> None:
    lines = _lines(base_csv())
    with backend.client() as c:
        sc = _new_spacecraft(c)
        body = _csv([lines[0] + ",hk_heater"] + [x + ",nan" for x in lines[1:11]])
        r = c.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers=CSV)
        job = _retrain(c, sc, method="linear")
    assert r.status_code in (200, 422), r.text  # 422 once "all rows rejected" is one
    rejected = r.json().get("rejected") or r.json().get("errors")
    assert len(rejected) == 10 and "hk_heater" in str(rejected[0])
    assert backend.stored(sc) == N
    assert _succeeded(job)["rows"]["used"] == N


def test_a_single_odd_row_among_thousands(backend: Backend) -> None:
    lines = _lines(base_csv(3000, 2))
    cells = lines[2000].split(",")
    cells[1:4] = [f"{3 * float(v):.3f}" for v in cells[1:4]]  # a glitch: 3x the field
    lines[2000] = ",".join(cells)
    with backend.client() as c:
        sc = _new_spacecraft(c, lines)
        result = _succeeded(_retrain(c, sc, method="linear"))
    assert result["promoted"] and result["rows"]["used"] == 2999
    assert result["rows"]["excluded"] == {"outlier": 1}
    assert result["holdout_rms_nt"] < 5.0  # 11.4 nT when the fit followed the odd row
    assert backend.stored(sc) == 3000


def test_retraining_again_on_the_same_data_is_not_promoted(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        _succeeded(_retrain(c, sc, method="linear"))
        again = _succeeded(_retrain(c, sc, method="linear", seed=1))
        versions = c.get(f"/v1/spacecraft/{sc}/calibrations").json()
    assert not again["promoted"] and again["rule"] == "margin"
    assert "does not beat version 1" in again["reason"] and "needs > 1 %" in again["reason"]
    assert [v["status"] for v in versions] == ["rejected", "in_service"]
    assert versions[0]["provenance"]["comparison"]["rule"] == "margin"


# ---------------------------------------------------------------------------------------------
# Quarantine, release, delete


def _t_iso(i: int) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(T0_UTC_S + DT_S * i))


def test_quarantine_round_trip_counts_and_excludes_from_retraining(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        rev = backend.revision(sc)
        r = c.post(
            f"/v1/spacecraft/{sc}/quarantines",
            json={"start": _t_iso(100), "end": _t_iso(199), "reason": "magnetorquer test"},
        )
        assert r.status_code == 201, r.text
        q = r.json()
        assert q["n_samples"] == 100 and q["active"] and q["created_by"] == "bootstrap admin"
        assert backend.revision(sc) == rev + 1
        listed = c.get(f"/v1/spacecraft/{sc}/quarantines").json()
        assert [x["id"] for x in listed] == [q["id"]]
        result = _succeeded(_retrain(c, sc, method="linear"))
        assert result["rows"]["used"] == N - 100
        assert result["rows"]["excluded"] == {"quarantined": 100}
        r = c.delete(f"/v1/spacecraft/{sc}/quarantines/{q['id']}")
        assert r.status_code == 200, r.text
        released = r.json()
        assert released["n_released"] == 100 and not released["active"]
        assert released["released_by"] == "bootstrap admin"
        assert backend.revision(sc) == rev + 2
        again = _succeeded(_retrain(c, sc, method="linear"))
        audit = c.get(f"/v1/spacecraft/{sc}/data-audit").json()
    assert again["rows"]["used"] == N and again["rows"]["excluded"] == {}
    assert [(a["action"], a["n_samples"], a["who"]) for a in audit] == [
        ("release", 100, "bootstrap admin"),
        ("quarantine", 100, "bootstrap admin"),
    ]
    assert (
        audit[1]["start"].startswith(_t_iso(100)[:19]) and audit[1]["reason"] == "magnetorquer test"
    )
    assert backend.stored(sc) == N  # quarantine never deletes


def test_releasing_twice_is_a_conflict_and_an_unknown_id_is_404(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        q = c.post(
            f"/v1/spacecraft/{sc}/quarantines", json={"start": T0_UTC_S, "end": T0_UTC_S + 50}
        ).json()
        assert q["n_samples"] == 6
        assert c.delete(f"/v1/spacecraft/{sc}/quarantines/{q['id']}").status_code == 200
        r = c.delete(f"/v1/spacecraft/{sc}/quarantines/{q['id']}")
        assert r.status_code == 409
        assert f"quarantine {q['id']} was already released by bootstrap admin" in r.json()["detail"]
        r = c.delete(f"/v1/spacecraft/{sc}/quarantines/999999")
        assert r.status_code == 404 and "has no quarantine 999999" in r.json()["detail"]
        audit = c.get(f"/v1/spacecraft/{sc}/data-audit").json()
    assert [a["action"] for a in audit] == ["release", "quarantine"]


#: Ids no quarantine can have: not positive, or beyond the 32-bit primary key (2^31 and more once
#: answered 500 on PostgreSQL, "integer out of range", and 2^63 and more on SQLite, OverflowError).
OUT_OF_RANGE_IDS = ["0", "-1", str(2**31), str(2**63), str(10**30)]


def test_an_out_of_range_quarantine_id_is_422_and_releases_nothing(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        q = c.post(f"/v1/spacecraft/{sc}/quarantines", json={"start": T0_UTC_S, "end": T0_UTC_S})
        assert q.status_code == 201, q.text
        rev = backend.revision(sc)
        for qid in OUT_OF_RANGE_IDS:
            r = c.delete(f"/v1/spacecraft/{sc}/quarantines/{qid}")
            assert r.status_code == 422, (qid, r.text)
            assert r.json()["errors"][0]["field"] == "path.quarantine_id", r.text
        active = c.get(f"/v1/spacecraft/{sc}/quarantines", params={"active": True}).json()
    assert [a["id"] for a in active] == [q.json()["id"]]
    assert backend.revision(sc) == rev


#: Numbers no body may carry: JSON 1e400 reads as infinity (PostgreSQL refused it inside the stored
#: schedule or job parameters: 500; SQLite stored null), integers beyond 64 bits.
HUGE = "1" + "0" * 400
SCHEDULE = '{"id": "@", "schedule": {%s}}'
OUT_OF_RANGE_BODIES: list[tuple[str, str, str, str]] = [
    ("infinite cadence", "", SCHEDULE % '"cadence_s": 1e400', "schedule.cadence_s"),
    ("infinite window", "", SCHEDULE % '"window_s": 1e400', "schedule.window_s"),
    ("huge sample count", "", SCHEDULE % f'"min_new_samples": 1{"0" * 30}', "min_new_samples"),
    ("infinite retrain window", "/calibrations", '{"window_s": 1e400}', "body.window_s"),
    ("huge quarantine start", "/quarantines", f'{{"start": {HUGE}, "end": 1}}', "body.start"),
    ("huge quarantine end", "/quarantines", f'{{"start": 0, "end": -{HUGE}}}', "body.end"),
]


@pytest.mark.parametrize(
    ("case", "path", "body", "field"), OUT_OF_RANGE_BODIES, ids=[b[0] for b in OUT_OF_RANGE_BODIES]
)
def test_an_out_of_range_number_in_a_body_is_422_naming_it_and_stores_nothing(
    backend: Backend, case: str, path: str, body: str, field: str
) -> None:
    sc = f"sat-{next(_COUNTER)}"
    with backend.client() as c:
        if path:  # a route of an existing spacecraft
            assert c.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE}).status_code == 201
            url = f"/v1/spacecraft/{sc}{path}"
        else:  # the spacecraft's own registration
            url, body = "/v1/spacecraft", body.replace("@", sc)
        jobs = int(backend.sql("SELECT COUNT(*) FROM jobs"))
        r = c.post(url, content=body, headers={"content-type": "application/json"})
        assert r.status_code == 422, (case, r.text)
        assert field in r.json()["errors"][0]["field"], (case, r.text)
        assert (c.get(f"/v1/spacecraft/{sc}").status_code == 200) == bool(path)
    assert int(backend.sql("SELECT COUNT(*) FROM jobs")) == jobs
    if path:
        assert backend.quarantines(sc) == 0


def test_delete_by_range_counts_and_removes_for_good(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        rev = backend.revision(sc)
        r = c.delete(
            f"/v1/spacecraft/{sc}/telemetry", params={"start": _t_iso(0), "end": _t_iso(49)}
        )
        assert r.status_code == 200, r.text
        assert r.json()["deleted"] == 50
        assert backend.stored(sc) == N - 50 and backend.revision(sc) == rev + 1
        assert c.get(f"/v1/spacecraft/{sc}").json()["samples"] == N - 50
        # the same range again deletes nothing (and says so)
        r = c.delete(
            f"/v1/spacecraft/{sc}/telemetry", params={"start": _t_iso(0), "end": _t_iso(49)}
        )
        assert r.status_code == 200 and r.json()["deleted"] == 0
        audit = c.get(f"/v1/spacecraft/{sc}/data-audit").json()
    assert [(a["action"], a["n_samples"]) for a in audit] == [("delete", 0), ("delete", 50)]


def test_deleting_the_2149_row_leaves_a_clean_window(backend: Backend) -> None:
    t_future = 5_600_000_000.0
    with backend.client() as c:
        sc = _new_spacecraft(c, [*_lines(base_csv()), _row_at(t_future)])
        r = c.delete(
            f"/v1/spacecraft/{sc}/telemetry",
            params={"start": str(t_future - 1), "end": str(t_future + 1)},
        )
        assert r.status_code == 200 and r.json()["deleted"] == 1
        result = _succeeded(_retrain(c, sc))
    assert result["rows"]["excluded"] == {} and result["rows"]["used"] == N
    assert backend.stored(sc) == N


def test_quarantining_everything_fails_the_retraining_and_keeps_the_calibration(
    backend: Backend,
) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        _succeeded(_retrain(c, sc, method="linear"))
        served = c.get(f"/v1/spacecraft/{sc}/calibration").json()
        r = c.post(
            f"/v1/spacecraft/{sc}/quarantines",
            json={"start": "2000-01-01T00:00:00Z", "end": "2100-01-01T00:00:00+00:00"},
        )
        assert r.status_code == 201 and r.json()["n_samples"] == N
        job = _retrain(c, sc, method="linear")
        assert job["status"] == "failed"
        assert job["error"] == f"NotEnoughDataError: spacecraft {sc} has no usable telemetry yet"
        assert c.get(f"/v1/spacecraft/{sc}/calibration").json() == served
    assert backend.stored(sc) == N


# ---------------------------------------------------------------------------------------------
# Scopes and bad requests: refused with a clear answer, nothing stored


@pytest.fixture(scope="module")
def keys(backend: Backend) -> dict[str, str]:
    out = {}
    with backend.client() as c:
        for name, scopes in {
            "reader": ["read:*"],
            "other": ["ingest:someone-else", "read:someone-else"],
            "writer": ["ingest:*", "read:*"],
        }.items():
            r = c.post("/v1/keys", json={"name": name, "scopes": scopes})
            assert r.status_code == 201, r.text
            out[name] = r.json()["key"]
    return out


def test_a_read_key_may_list_but_not_quarantine_release_or_delete(
    backend: Backend, keys: dict[str, str]
) -> None:
    with backend.client() as admin:
        sc = _new_spacecraft(admin)
        q = admin.post(
            f"/v1/spacecraft/{sc}/quarantines", json={"start": T0_UTC_S, "end": T0_UTC_S + 9}
        ).json()
    with backend.client(keys["reader"]) as c:
        r1 = c.post(f"/v1/spacecraft/{sc}/quarantines", json={"start": 0, "end": 1e10})
        r2 = c.delete(f"/v1/spacecraft/{sc}/quarantines/{q['id']}")
        r3 = c.delete(f"/v1/spacecraft/{sc}/telemetry", params={"start": "0", "end": "1e10"})
        listed = c.get(f"/v1/spacecraft/{sc}/quarantines")
        audit = c.get(f"/v1/spacecraft/{sc}/data-audit")
    for r in (r1, r2, r3):
        assert (
            r.status_code == 403 and r.json()["detail"] == f"this key lacks the scope ingest:{sc}"
        )
    assert listed.status_code == 200 and listed.json()[0]["active"]
    assert audit.status_code == 200 and len(audit.json()) == 1
    assert backend.stored(sc) == N and backend.quarantines(sc) == 1


def test_a_key_of_another_spacecraft_cannot_touch_its_samples(
    backend: Backend, keys: dict[str, str]
) -> None:
    with backend.client() as admin:
        sc = _new_spacecraft(admin)
    with backend.client(keys["other"]) as c:
        r1 = c.post(f"/v1/spacecraft/{sc}/quarantines", json={"start": 0, "end": 1e10})
        r2 = c.delete(f"/v1/spacecraft/{sc}/telemetry", params={"start": "0", "end": "1e10"})
        r3 = c.get(f"/v1/spacecraft/{sc}/quarantines")
    assert r1.status_code == 403 and r2.status_code == 403
    assert r3.status_code == 403 and r3.json()["detail"] == f"this key lacks the scope read:{sc}"
    assert backend.stored(sc) == N and backend.quarantines(sc) == 0


def test_a_write_key_is_named_in_the_audit(backend: Backend, keys: dict[str, str]) -> None:
    with backend.client() as admin:
        sc = _new_spacecraft(admin)
    with backend.client(keys["writer"]) as c:
        r = c.post(f"/v1/spacecraft/{sc}/quarantines", json={"start": T0_UTC_S, "end": T0_UTC_S})
        audit = c.get(f"/v1/spacecraft/{sc}/data-audit").json()
    assert r.status_code == 201 and r.json()["created_by"] == "writer"
    assert r.json()["n_samples"] == 1
    assert audit[0]["who"] == "writer" and audit[0]["action"] == "quarantine"


def test_no_key_is_401_and_changes_nothing(backend: Backend) -> None:
    with backend.client() as admin:
        sc = _new_spacecraft(admin)
    with backend.client(None) as c:
        r1 = c.post(f"/v1/spacecraft/{sc}/quarantines", json={"start": 0, "end": 1e10})
        r2 = c.delete(f"/v1/spacecraft/{sc}/telemetry", params={"start": "0", "end": "1e10"})
    for r in (r1, r2):
        assert r.status_code == 401 and r.json()["detail"] == "missing X-API-Key header"
    assert backend.stored(sc) == N and backend.quarantines(sc) == 0


BAD_RANGES: list[tuple[str, dict[str, Any], str, str]] = [
    ("end before start", {"start": 100.0, "end": 99.0}, "end", "the range ends before it starts"),
    ("no UTC offset", {"start": "2022-08-01T00:00:00", "end": 1e10}, "start", "needs a UTC offset"),
    ("not a time", {"start": "yesterday", "end": 1e10}, "start", "is not an ISO-8601 time"),
    ("beyond 1e11 s", {"start": 0, "end": 1e300}, "end", "not a finite time"),
]


@pytest.mark.parametrize(
    ("case", "body", "field", "message"), BAD_RANGES, ids=[b[0] for b in BAD_RANGES]
)
def test_a_bad_quarantine_range_is_422_naming_the_field(
    backend: Backend, case: str, body: dict[str, Any], field: str, message: str
) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        rev = backend.revision(sc)
        r = c.post(f"/v1/spacecraft/{sc}/quarantines", json=body)
    assert r.status_code == 422, (case, r.text)
    assert r.json()["detail"].startswith(f"{field}: ") and message in r.json()["detail"]
    assert r.json()["errors"][0]["field"] == field
    assert backend.quarantines(sc) == 0 and backend.revision(sc) == rev


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_non_finite_delete_bound_is_422_and_deletes_nothing(backend: Backend, value: str) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        r = c.delete(f"/v1/spacecraft/{sc}/telemetry", params={"start": "0", "end": value})
    assert r.status_code == 422 and r.json()["detail"].startswith("end: ")
    assert "not a finite time" in r.json()["detail"]
    assert backend.stored(sc) == N


def test_an_unknown_field_in_the_quarantine_body_is_422(backend: Backend) -> None:
    with backend.client() as c:
        sc = _new_spacecraft(c)
        r = c.post(
            f"/v1/spacecraft/{sc}/quarantines", json={"start": 0, "end": 1, "spacecraft": "x"}
        )
    assert r.status_code == 422 and "spacecraft" in r.json()["detail"]
    assert backend.quarantines(sc) == 0


def test_an_unknown_spacecraft_is_404(backend: Backend) -> None:
    with backend.client() as c:
        r1 = c.post("/v1/spacecraft/nobody/quarantines", json={"start": 0, "end": 1})
        r2 = c.delete("/v1/spacecraft/nobody/telemetry", params={"start": "0", "end": "1"})
        r3 = c.get("/v1/spacecraft/nobody/quarantines")
    for r in (r1, r2, r3):
        assert r.status_code == 404 and r.json()["detail"] == "unknown spacecraft 'nobody'"


def test_quarantined_rows_leave_the_residuals_and_diagnosis_window(backend: Backend) -> None:
    """``/residuals`` and the diagnosis read the same window (``_recent_telemetry``)."""
    with backend.client() as c:
        sc = _new_spacecraft(c)
        _succeeded(_retrain(c, sc, method="linear"))
        before = c.get(f"/v1/spacecraft/{sc}/residuals", params={"max_points": 20000}).json()
        r = c.post(
            f"/v1/spacecraft/{sc}/quarantines", json={"start": _t_iso(300), "end": _t_iso(399)}
        )
        assert r.status_code == 201 and r.json()["n_samples"] == 100
        after = c.get(f"/v1/spacecraft/{sc}/residuals", params={"max_points": 20000})
    assert after.status_code == 200, after.text
    t = after.json()["t_utc_s"]
    assert len(before["t_utc_s"]) == N and len(t) == N - 100
    lo, hi = T0_UTC_S + DT_S * 300, T0_UTC_S + DT_S * 399
    assert not any(lo <= x <= hi for x in t)
    assert after.json()["rms_nt"] < 5.0
    assert backend.stored(sc) == N
