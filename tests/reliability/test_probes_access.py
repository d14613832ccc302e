"""Black-box probes of names, scopes, rate limits, cache keys, methods and retraining conflicts
against a real ``orbitcal serve`` process (framework: ``probes.py``).

Each probe asserts the status, the words of the message and the stored state afterwards (no
spacecraft, key or job created by a refused request; a data revision bumped only by new rows; the
rate limiter's answer across processes). Classes: ``names`` (spacecraft ids), ``scopes``,
``method``, ``retrain-conflict``, ``cache``, ``rate-limit`` (one process, and two processes on one
Redis), ``orbit`` (unphysical OMM elements).
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import sqlalchemy as sa
from probes import RESULTS, Probe, ProbeResult, ServeProcess, serve_process
from reliability_helpers import ADMIN_KEY, SWARM_A_TLE, T0_UTC_S, csv_batch, physical_csv
from shared_worlds import SWARM_A_2022_OMM

CSV = {"content-type": "text/csv"}
JSON = {"content-type": "application/json"}
ISS_TLE = (
    "1 25544U 98067A   22213.47757853  .00004606  00000+0  88053-4 0  9999\n"
    "2 25544  51.6434 112.2418 0005228  73.0757 103.9555 15.50193086352208"
)


def _scalar(server: ServeProcess, sql: str, **params: Any) -> Any:
    with server.engine.connect() as conn:
        return conn.execute(sa.text(sql), params).scalar_one()


def _json(value: Any) -> bytes:
    import json

    return json.dumps(value).encode()


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServeProcess]:
    with serve_process(tmp_path_factory.mktemp("probes-access")) as s:
        yield s


# --- names: spacecraft ids ---------------------------------------------------------------------


def _no_spacecraft(sc_id: str) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, _sc: str, r: httpx.Response) -> None:
        n = _scalar(server, "SELECT COUNT(*) FROM spacecraft WHERE id = :i", i=sc_id)
        assert n == 0, f"refused id {sc_id!r} was stored"
        assert r.json()["errors"][0]["field"] == "body.id", r.text

    return check


def _one_spacecraft(sc_id: str) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, _sc: str, r: httpx.Response) -> None:
        assert r.json()["id"] == sc_id
        assert _scalar(server, "SELECT COUNT(*) FROM spacecraft WHERE id = :i", i=sc_id) == 1
        with server.client() as http:  # and it works as one URL path segment
            assert http.get(f"/v1/spacecraft/{sc_id}").json()["id"] == sc_id

    return check


BAD_IDS = {
    "dot": ".",
    "dotdot": "..",
    "slash": "a/b",
    "trailing-newline": "sat-1\n",
    "space": "sat 1",
    "empty": "",
    "65-chars": "a" * 65,
    "leading-dash": "-sat",
    "leading-dot": ".sat",
    "non-ascii": "sät-1",
    "percent": "%2e%2e",
    "nul": "a\x00b",
    "backslash": "a\\b",
    "query": "a?b=1",
}


def _id_probe(name: str, sc_id: str) -> Probe:
    return Probe(
        f"id-{name}",
        "names",
        _json({"id": sc_id}),
        JSON,
        422,
        says=("body.id",),
        stored=None,
        path="/v1/spacecraft",
        check=_no_spacecraft(sc_id),
    )


GOOD_IDS = {"64-chars": "A" * 64, "all-classes": "sat.1_A-b", "digit-first": "0sat"}

NAME_PROBES = [_id_probe(k, v) for k, v in BAD_IDS.items()] + [
    Probe(
        f"id-ok-{k}",
        "names",
        _json({"id": v}),
        JSON,
        201,
        stored=None,
        path="/v1/spacecraft",
        check=_one_spacecraft(v),
    )
    for k, v in GOOD_IDS.items()
]


@pytest.mark.parametrize("probe", NAME_PROBES, ids=lambda p: p.name)
def test_names(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


# --- scopes ------------------------------------------------------------------------------------


def _keys_unchanged(name: str) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, _sc: str, r: httpx.Response) -> None:
        assert _scalar(server, "SELECT COUNT(*) FROM api_keys WHERE name = :n", n=name) == 0
        assert r.json()["errors"][0]["field"] == "body.scopes", r.text

    return check


BAD_SCOPES = {
    "admin-newline": ["admin\n"],
    "admin-space": [" admin"],
    "admin-case": ["Admin"],
    "admin-nul": ["admin\x00"],
    "read-dotdot": ["read:.."],
    "ingest-slash": ["ingest:a/b"],
    "unknown-action": ["write:sat-1"],
    "read-empty-id": ["read:"],
    "star-newline": ["read:*\n"],
    "admin-with-id": ["admin:sat-1"],
}


def _scope_probe(name: str, scopes: list[str], index: int = 0) -> Probe:
    key_name = f"scope-probe-{name}"
    return Probe(
        f"scope-{name}",
        "scopes",
        _json({"name": key_name, "scopes": scopes}),
        JSON,
        422,
        says=("body.scopes", f"scopes[{index}]"),
        stored=None,
        path="/v1/keys",
        check=_keys_unchanged(key_name),
    )


def _key_stored(scopes: list[str]) -> Callable[[ServeProcess, str, httpx.Response], None]:
    def check(server: ServeProcess, _sc: str, r: httpx.Response) -> None:
        import json

        assert r.json()["scopes"] == sorted(scopes)
        stored = _scalar(server, "SELECT scopes FROM api_keys WHERE name = :n", n="scope-ok")
        assert sorted(json.loads(stored) if isinstance(stored, str) else stored) == sorted(scopes)

    return check


SCOPE_PROBES = [_scope_probe(k, v) for k, v in BAD_SCOPES.items()] + [
    _scope_probe("second-bad", ["read:sat-1", "admin\n"], index=1),
    Probe(
        "scope-ok",
        "scopes",
        _json({"name": "scope-ok", "scopes": ["read:sat-1", "ingest:*"]}),
        JSON,
        201,
        stored=None,
        path="/v1/keys",
        check=_key_stored(["read:sat-1", "ingest:*"]),
    ),
]


@pytest.mark.parametrize("probe", SCOPE_PROBES, ids=lambda p: p.name)
def test_scopes(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


# --- method: unknown method is a 422 at request time ------------------------------------------


def _no_job(server: ServeProcess, sc: str, r: httpx.Response) -> None:
    n = _scalar(
        server,
        "SELECT COUNT(*) FROM jobs j JOIN spacecraft c ON c.pk = j.spacecraft_pk WHERE c.id = :s",
        s=sc,
    )
    assert n == 0, f"{n} jobs created by a refused retraining"
    assert r.json()["errors"][0]["field"] == "method", r.text


METHOD_PROBES = [
    Probe(
        f"method-{name}",
        "method",
        _json({"method": method}),
        JSON,
        422,
        says=("unknown calibration method", "known: linear"),
        stored=0,
        path="/v1/spacecraft/{sc}/calibrations",
        check=_no_job,
    )
    for name, method in {
        "nope": "nope",
        "empty": "",
        "case": "LINEAR",
        "newline": "linear\n",
        "spaces": " linear",
    }.items()
]


@pytest.mark.parametrize("probe", METHOD_PROBES, ids=lambda p: p.name)
def test_unknown_method(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


# --- orbit: unphysical OMM elements are 422s naming the field ----------------------------------

OMM = SWARM_A_2022_OMM  # tests/shared_worlds.py


def _orbit_unchanged(server: ServeProcess, sc: str, r: httpx.Response) -> None:
    tle, omm = (
        server.engine.connect()
        .execute(sa.text("SELECT tle, omm FROM spacecraft WHERE id = :s"), {"s": sc})
        .one()
    )
    assert tle is None and omm in (None, "null"), "a refused orbit was stored"
    field = r.json()["errors"][0].get("field", "")
    assert field.startswith("omm.") and field[4:] in r.json()["detail"], r.text


ORBIT_PROBES = [
    Probe(
        f"omm-{name}",
        "orbit",
        _json({"omm": {**OMM, field: value}}),
        JSON,
        422,
        says=(field,),
        stored=0,
        method="PUT",
        path="/v1/spacecraft/{sc}/orbit",
        check=_orbit_unchanged,
    )
    for name, field, value in [
        ("mean-motion-nan", "MEAN_MOTION", "nan"),
        ("mean-motion-negative", "MEAN_MOTION", -15.3),
        ("mean-motion-inf", "MEAN_MOTION", "inf"),
        ("eccentricity-1.5", "ECCENTRICITY", 1.5),
        ("eccentricity-negative", "ECCENTRICITY", -0.1),
        ("element-set-1e30", "ELEMENT_SET_NO", 10**30),
        ("inclination-text", "INCLINATION", "steep"),
    ]
]


@pytest.mark.parametrize("probe", ORBIT_PROBES, ids=lambda p: p.name)
def test_orbit(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


# --- cache keys: the data revision, the calibration's ETag, the diagnosis after PUT /orbit ----


def _revision(server: ServeProcess, sc: str) -> int:
    return int(_scalar(server, "SELECT data_revision FROM spacecraft WHERE id = :s", s=sc))


def _record(server: ServeProcess, name: str, klass: str, r: httpx.Response, stored: int) -> None:
    """Count a request made outside :meth:`ServeProcess.run` in the per-class summary."""
    rss = server.peak_rss_mb()
    RESULTS.append(
        ProbeResult(
            name=name,
            klass=klass,
            database=server.database,
            status=r.status_code,
            detail=r.text[:500],
            stored=stored,
            body_bytes=0,
            rss_before_mb=rss,
            peak_rss_mb=rss,
            seconds=r.elapsed.total_seconds(),
            alive=server.alive(),
        )
    )


def test_data_revision_moves_with_new_rows_only(server: ServeProcess) -> None:
    sc = server.new_spacecraft("rev", tle=SWARM_A_TLE)
    assert _revision(server, sc) == 0
    batch = csv_batch(T0_UTC_S, 5)
    first = server.run(
        Probe("revision-new-rows", "cache", batch, CSV, 200, says=('"accepted":5',), stored=5,
              spacecraft=sc)
    )  # fmt: skip
    assert first.status == 200 and _revision(server, sc) == 1
    server.run(
        Probe("revision-duplicates", "cache", batch, CSV, 200, says=('"duplicates":5',), stored=0,
              spacecraft=sc)
    )  # fmt: skip
    assert _revision(server, sc) == 1, "an upload of duplicates only changed the revision"
    server.run(
        Probe("revision-more-rows", "cache", csv_batch(T0_UTC_S + 100, 3), CSV, 200, stored=3,
              spacecraft=sc)
    )  # fmt: skip
    assert _revision(server, sc) == 2


def _without_positions(csv: bytes) -> bytes:
    """Drop the r_x, r_y, r_z columns (the last three), so the spacecraft's orbit is used."""
    return b"\n".join(b",".join(line.split(b",")[:-3]) for line in csv.splitlines()) + b"\n"


@pytest.fixture(scope="module")
def calibrated(server: ServeProcess) -> str:
    """A spacecraft with 600 calibratable samples (100 min at 10 s, positions from its TLE) and
    a linear calibration in service."""
    sc = server.new_spacecraft("cal", tle=SWARM_A_TLE)
    body = _without_positions(physical_csv(T0_UTC_S, 600))
    assert body.splitlines()[0] == b"time,b_x,b_y,b_z,q_w,q_x,q_y,q_z"
    with server.client() as http:
        r = http.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers=CSV)
        assert r.json()["accepted"] == 600, r.text
        job = http.post(f"/v1/spacecraft/{sc}/calibrations").json()["job_id"]
        _wait_job(http, job)
    return sc


def _wait_job(http: httpx.Client, job_id: str, timeout_s: float = 300) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        job = http.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in ("succeeded", "failed"):
            return job  # type: ignore[no-any-return]
        assert time.monotonic() < deadline, f"job {job_id} still {job['status']}"
        time.sleep(0.2)


def test_calibration_etag_and_304(server: ServeProcess, calibrated: str) -> None:
    with server.client() as http:
        r = http.get(f"/v1/spacecraft/{calibrated}/calibration")
        assert r.status_code == 200 and r.json()["spacecraft"] == calibrated
        etag = r.headers["etag"]
        assert etag.startswith(f'"v{r.json()["version"]}-')
        for _ in range(3):  # the route, then the in-memory shortcut: the same answer
            again = http.get(f"/v1/spacecraft/{calibrated}/calibration")
            assert again.content == r.content and again.headers["etag"] == etag
        nm = http.get(f"/v1/spacecraft/{calibrated}/calibration",
                      headers={"If-None-Match": etag})  # fmt: skip
        _record(server, "calibration-if-none-match", "cache", nm, 0)
        assert nm.status_code == 304 and nm.content == b"" and nm.headers["etag"] == etag
        other = http.get(f"/v1/spacecraft/{calibrated}/calibration",
                         headers={"If-None-Match": '"v0-0000"'})  # fmt: skip
        assert other.status_code == 200 and other.content == r.content
    # the shortcut keeps scopes: a key of another spacecraft gets 403, no key 401
    with server.client() as http:
        other_key = http.post("/v1/keys", json={"name": "etag-other", "scopes": ["read:zz"]})
    with server.client(other_key.json()["key"]) as http:
        r403 = http.get(f"/v1/spacecraft/{calibrated}/calibration")
    _record(server, "calibration-other-scope", "cache", r403, 0)
    assert r403.status_code == 403 and f"read:{calibrated}" in r403.json()["detail"]
    with server.client(None) as http:
        assert http.get(f"/v1/spacecraft/{calibrated}/calibration").status_code == 401


def test_diagnosis_is_recomputed_after_put_orbit(server: ServeProcess, calibrated: str) -> None:
    with server.client() as http:
        first = http.get(f"/v1/spacecraft/{calibrated}/diagnosis", timeout=900)
        assert first.status_code == 200, first.text
        same = http.get(f"/v1/spacecraft/{calibrated}/diagnosis", timeout=900)
        assert same.json() == first.json()  # cached: nothing changed
        r = http.put(f"/v1/spacecraft/{calibrated}/orbit", json={"tle": ISS_TLE})
        assert r.status_code == 200
        assert _scalar(server, "SELECT tle FROM spacecraft WHERE id = :s", s=calibrated) == ISS_TLE
        after = http.get(f"/v1/spacecraft/{calibrated}/diagnosis", timeout=900)
        _record(server, "diagnosis-after-put-orbit", "cache", after, 0)
        assert after.status_code == 200, after.text
        # The wrong orbit (ISS for Swarm A data) leaves a far larger baseline residual.
        rms_first = first.json()["baseline"]["holdout_rms_nt"]
        rms_after = after.json()["baseline"]["holdout_rms_nt"]
        assert rms_after > 10 * rms_first, (rms_first, rms_after)
        # and back: the orbit's digest is in the key, so the first report's inputs give it again
        assert http.put(f"/v1/spacecraft/{calibrated}/orbit", json={"tle": SWARM_A_TLE}).is_success
        back = http.get(f"/v1/spacecraft/{calibrated}/diagnosis", timeout=900)
        assert back.json()["baseline"]["holdout_rms_nt"] == pytest.approx(rms_first, rel=1e-9)


# --- retraining conflicts ----------------------------------------------------------------------


def _live_jobs(server: ServeProcess, sc: str) -> int:
    return int(
        _scalar(
            server,
            "SELECT COUNT(*) FROM jobs j JOIN spacecraft c ON c.pk = j.spacecraft_pk "
            "WHERE c.id = :s AND j.status IN ('queued', 'running')",
            s=sc,
        )
    )


def _running_job(server: ServeProcess, sc: str, method: str) -> str:
    """A job of ``sc`` in state ``running``, as a Celery worker running it would leave it."""
    job_id = uuid.uuid4().hex
    params = {"method": method, "field": "IGRF-14", "window_s": 86400.0, "holdout_fraction": 0.2,
              "min_samples": 200, "seed": 0}  # fmt: skip
    with server.engine.begin() as conn:
        pk = conn.execute(sa.text("SELECT pk FROM spacecraft WHERE id = :s"), {"s": sc}).scalar()
        conn.execute(
            sa.text(
                "INSERT INTO jobs (id, spacecraft_pk, kind, trigger, status, params, created_at, "
                "started_at) VALUES (:id, :pk, 'retrain', 'api', 'running', :p, :t, :t)"
            ),
            {"id": job_id, "pk": pk, "p": _json(params).decode(), "t": time.time()},
        )
    return job_id


def test_conflicting_retrain_is_409_naming_the_running_job(server: ServeProcess) -> None:
    sc = server.new_spacecraft("conflict", tle=SWARM_A_TLE)
    job_id = _running_job(server, sc, "linear")
    with server.client() as http:
        path = f"/v1/spacecraft/{sc}/calibrations"
        answers = {
            "conflict-method": http.post(path, json={"method": "twostep"}),
            "conflict-seed": http.post(path, json={"seed": 7}),
            "conflict-window": http.post(path, json={"window_s": 3600.0, "method": "linear"}),
            "same-method": http.post(path, json={"method": "linear"}),
            "no-parameters": http.post(path),
        }
    live = _live_jobs(server, sc)
    for name, r in answers.items():
        _record(server, name, "retrain-conflict", r, live)
    conflict = answers["conflict-method"].json()
    assert answers["conflict-method"].status_code == 409, conflict
    assert job_id in conflict["detail"] and conflict["job_id"] == job_id
    assert "method='linear'" in conflict["detail"] and "'twostep'" in conflict["detail"]
    assert conflict["errors"][0]["field"] == "method"
    for name, field in [("conflict-seed", "seed"), ("conflict-window", "window_s")]:
        r = answers[name]
        assert r.status_code == 409 and job_id in r.json()["detail"], r.text
        assert r.json()["errors"][0]["field"] == field
    for name in ("same-method", "no-parameters"):  # the same retraining: the running job's id
        assert answers[name].status_code == 202 and answers[name].json()["job_id"] == job_id
    assert live == 1, f"{live} live jobs for one spacecraft"
    # once it has finished, the other method is accepted as a new job
    with server.engine.begin() as conn:
        conn.execute(sa.text("UPDATE jobs SET status = 'failed' WHERE id = :i"), {"i": job_id})
    with server.client() as http:
        r = http.post(f"/v1/spacecraft/{sc}/calibrations", json={"method": "twostep"})
        assert r.status_code == 202 and r.json()["job_id"] != job_id
        assert _wait_job(http, r.json()["job_id"])["params"]["method"] == "twostep"


# --- rate limiting: failed authentication per address, across processes on Redis -------------

LIMITED = {
    "ORBITCAL_RATE_LIMIT_PER_S": "2",
    "ORBITCAL_RATE_LIMIT_BURST": "10",
    # one failure refilled per 1000 s: none refills while a test counts (a refill mid-loop made
    # the counts depend on the machine's speed); the refill itself is tested with a fake clock
    "ORBITCAL_AUTH_FAIL_PER_S": "0.001",
    "ORBITCAL_AUTH_FAIL_BURST": "8",
}


def _fresh_wrong_key() -> str:
    return "ock_" + uuid.uuid4().hex + uuid.uuid4().hex[:11]


def test_fresh_wrong_keys_do_not_bypass_the_limit(tmp_path: Path) -> None:
    with (
        serve_process(tmp_path, env=LIMITED) as s,
        httpx.Client(base_url=s.url, timeout=30) as http,
    ):
        answers = [
            http.get("/v1/spacecraft", headers={"X-API-Key": _fresh_wrong_key()}) for _ in range(12)
        ]
        statuses = [r.status_code for r in answers]
        blocked = answers[-1]
        _record(s, "fresh-wrong-keys", "rate-limit", blocked, 0)
        assert statuses[:8] == [401] * 8, statuses
        assert statuses[8:] == [429] * 4, statuses
        assert "failed authentications" in blocked.json()["detail"]
        assert int(blocked.headers["retry-after"]) >= 1
        # no key at all is a failed authentication too, and /healthz stays open
        nokey = http.get("/v1/spacecraft")
        _record(s, "no-key-while-blocked", "rate-limit", nokey, 0)
        assert nokey.status_code == 429
        assert http.get("/healthz").status_code == 200
        # nothing was created by the failed calls
        post = http.post("/v1/spacecraft", json={"id": "x1"},
                         headers={"X-API-Key": _fresh_wrong_key()})  # fmt: skip
        assert post.status_code == 429
        assert _scalar(s, "SELECT COUNT(*) FROM spacecraft") == 0
        # a valid key from the same address is never refused by the failure limit
        r = http.get("/v1/spacecraft", headers={"X-API-Key": ADMIN_KEY})
        _record(s, "valid-key-while-blocked", "rate-limit", r, 0)
        assert r.status_code == 200, r.text
        # and the wrong ones are still refused afterwards
        again = http.get("/v1/spacecraft", headers={"X-API-Key": _fresh_wrong_key()})
        assert again.status_code == 429


def test_failure_bucket_refills_at_its_rate() -> None:
    """The refill, on a clock the test moves (no sleep, no dependence on the machine's speed)."""
    import asyncio

    from service.ratelimit import MemoryBuckets

    now = [1000.0]
    store = MemoryBuckets(clock=lambda: now[0])

    def take(cost: float) -> float:
        return asyncio.run(store.take("authfail:addr:x", 0.5, 8, cost=cost))

    assert [take(1.0) for _ in range(8)] == [0.0] * 8
    wait = take(0.0)
    assert wait == pytest.approx(2.0)  # one token at 0.5/s
    now[0] += 1.9
    assert take(0.0) == pytest.approx(0.1)  # 0.95 token refilled
    now[0] += 0.2
    assert take(1.0) == 0.0  # 1.05 tokens: one more failure allowed
    assert take(0.0) == pytest.approx(1.9)  # 0.05 left


def test_valid_keys_do_not_spend_the_failure_budget(tmp_path: Path) -> None:
    with serve_process(tmp_path, env={**LIMITED, "ORBITCAL_RATE_LIMIT_BURST": "40"}) as s:
        with s.client() as admin:
            statuses = [admin.get("/v1/spacecraft").status_code for _ in range(20)]
            r = admin.get("/v1/spacecraft/nope")
        _record(s, "valid-key-404s", "rate-limit", r, 0)
        assert statuses == [200] * 20 and r.status_code == 404


@pytest.mark.services
def test_limits_hold_across_two_processes_on_redis(tmp_path: Path) -> None:
    from reliability_helpers import require_service

    require_service("Redis", 6379)
    db = tmp_path / "shared.sqlite"
    env = {
        **LIMITED,
        "ORBITCAL_RATE_LIMIT_REDIS_URL": "redis://127.0.0.1:6379/0",
        "ORBITCAL_DATABASE_URL": f"sqlite:///{db}",
    }
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with (
        serve_process(tmp_path / "a", env=env, args=("--database", f"sqlite:///{db}")) as a,
        serve_process(tmp_path / "b", env=env, args=("--database", f"sqlite:///{db}")) as b,
    ):
        # failed authentication: 8 in total across both processes, then 429 from either
        statuses = []
        for i in range(12):
            target = (a, b)[i % 2]
            with httpx.Client(base_url=target.url, timeout=30) as http:
                r = http.get("/v1/spacecraft", headers={"X-API-Key": _fresh_wrong_key()})
                statuses.append(r.status_code)
        _record(a, "redis-fresh-wrong-keys", "rate-limit", r, 0)
        assert statuses[:8] == [401] * 8 and statuses[8:] == [429] * 4, statuses
        assert "failed authentications" in r.json()["detail"]
        # per key: a burst of 10 shared by both processes (each alone would allow 10)
        for s in (a, b):
            assert s.alive()
    # a fresh pair of processes on a new database = a new deployment with its own buckets
    db2 = tmp_path / "shared2.sqlite"
    # slow refill (0.2/s): unshared, each process would let its 8 of the 16 requests through
    env2 = {**env, "ORBITCAL_AUTH_FAIL_PER_S": "0", "ORBITCAL_RATE_LIMIT_PER_S": "0.2"}
    (tmp_path / "c").mkdir()
    (tmp_path / "d").mkdir()
    with (
        serve_process(tmp_path / "c", env=env2, args=("--database", f"sqlite:///{db2}")) as c,
        serve_process(tmp_path / "d", env=env2, args=("--database", f"sqlite:///{db2}")) as d,
    ):
        ok = 0
        t0 = time.monotonic()
        for i in range(16):
            with (c, d)[i % 2].client() as http:
                r = http.get("/v1/spacecraft")
                ok += r.status_code == 200
        elapsed_s = time.monotonic() - t0
        _record(c, "redis-per-key-burst", "rate-limit", r, 0)
        # one burst of 10 for both processes, plus what refilled at 0.2/s meanwhile
        assert 10 <= ok <= 10 + int(0.2 * elapsed_s) + 1 < 16, (ok, elapsed_s)
        assert r.status_code == 429 and "per key" in r.json()["detail"]


# --- several API processes: one elected for the per-deployment duties, limits shared ----------


def test_several_workers_need_shared_rate_limit_buckets(tmp_path: Path) -> None:
    from pydantic import SecretStr

    from service.app import create_app
    from service.settings import Settings

    common: dict[str, Any] = {
        "database_url": f"sqlite:///{tmp_path / 'w.sqlite'}",
        "admin_key": SecretStr(ADMIN_KEY),
        "workers": 2,
    }
    with pytest.raises(ValueError, match="ORBITCAL_RATE_LIMIT_REDIS_URL"):
        create_app(Settings(**common))
    create_app(Settings(**common, rate_limit_redis_url="redis://127.0.0.1:6379/0"))
    create_app(Settings(**common, rate_limit_per_s=0))


def test_one_process_per_deployment_takes_the_duties() -> None:
    from service.app import _deployment_lock

    deployment = "test-" + uuid.uuid4().hex[:12]
    first = _deployment_lock(deployment)
    assert first is not None
    assert _deployment_lock(deployment) is None  # a second process (or app) does not get it
    other = _deployment_lock(deployment + "-other")
    assert other is not None  # another database's processes do
    other.close()
    first.close()
    again = _deployment_lock(deployment)
    assert again is not None  # released when the holder goes away
    again.close()
