"""The HTTP surface over real HTTP (uvicorn on 127.0.0.1): ingest formats, idempotency, errors,
auth and scopes, limits, OpenAPI, health and metrics."""

from __future__ import annotations

import gzip
import io
import json
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from service_helpers import ADMIN_KEY, LiveServer, live_server, sqlite_settings
from service_worlds import T0_UTC_S, world
from shared_worlds import SWARM_A_2022_OMM

from orbitcal import ccsds
from service.app import create_app
from service.settings import Settings

CSV = {"content-type": "text/csv"}


def _encode(df: pd.DataFrame, fmt: str) -> tuple[bytes, str]:
    if fmt == "csv":
        return df.to_csv(index=False).encode(), "text/csv"
    if fmt == "ndjson":
        return df.to_json(
            orient="records", lines=True, double_precision=15
        ).encode(), "application/x-ndjson"
    if fmt == "json":
        return df.to_json(orient="records", double_precision=15).encode(), "application/json"
    if fmt == "parquet":
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        return buf.getvalue(), "application/vnd.apache.parquet"
    q = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    b = df[["b_x", "b_y", "b_z"]].to_numpy()
    return ccsds.encode_packets(df["time"].to_numpy(), b, q_wxyz=q), ccsds_type()


def ccsds_type() -> str:
    return "application/vnd.ccsds.space-packet"


def _register(server: LiveServer, sc: str = "sat-1") -> None:
    with server.client() as c:
        r = c.post("/v1/spacecraft", json={"id": sc})
        assert r.status_code == 201, r.text


def test_every_format_is_stored_and_duplicates_change_nothing(
    server: LiveServer, tmp_path: Path
) -> None:
    _register(server)
    df, _ = world(T0_UTC_S, 250)
    fmts = ["csv", "ndjson", "json", "parquet", "ccsds"]
    with server.client() as c:
        for i, fmt in enumerate(fmts):
            part = df.iloc[i * 50 : (i + 1) * 50]
            body, media = _encode(part, fmt)
            r = c.post(
                "/v1/spacecraft/sat-1/telemetry", content=body, headers={"content-type": media}
            )
            assert r.status_code == 200, (fmt, r.text)
            assert r.json() == {"accepted": 50, "duplicates": 0, "rejected": []}, fmt
        # the whole table again, in another format and shuffled: all duplicates, nothing changes
        body, media = _encode(df.sample(frac=1.0, random_state=3), "parquet")
        r = c.post("/v1/spacecraft/sat-1/telemetry", content=body, headers={"content-type": media})
        assert r.json() == {"accepted": 0, "duplicates": 250, "rejected": []}
        assert c.get("/v1/spacecraft/sat-1").json()["samples"] == 250
    con = sqlite3.connect(tmp_path / "orbitcal.sqlite")
    stored = con.execute("SELECT t_utc_us, b_x, q_w, r_x FROM samples ORDER BY t_utc_us").fetchall()
    con.close()
    assert len(stored) == 250
    np.testing.assert_array_equal([s[0] for s in stored], np.rint(df["time"] * 1e6).astype(int))
    # text formats carry 15 significant digits here; Parquet and CCSDS keep every bit
    np.testing.assert_allclose([s[1] for s in stored], df["b_x"], rtol=1e-14, atol=0)
    np.testing.assert_array_equal([s[1] for s in stored[150:]], df["b_x"][150:])
    assert [s[3] is None for s in stored] == [i >= 200 for i in range(250)]  # CCSDS has no r


def test_partly_bad_upload_keeps_the_valid_rows_and_names_the_bad_ones(server: LiveServer) -> None:
    _register(server)
    df, _ = world(T0_UTC_S, 6)
    df.loc[1, "b_y"] = np.inf
    df.loc[3, "q_w"] = 0.5  # non-unit quaternion
    with server.client() as c:
        r = c.post("/v1/spacecraft/sat-1/telemetry", content=df.to_csv(index=False), headers=CSV)
    assert r.status_code == 200
    body = r.json()
    assert body["accepted"] == 4 and body["duplicates"] == 0
    assert [e["row"] for e in body["rejected"]] == [1, 3]
    assert "b_y" in body["rejected"][0]["reason"]
    assert "quaternion" in body["rejected"][1]["reason"]


def test_time_scale_is_declared_not_guessed(server: LiveServer) -> None:
    _register(server)
    df, _ = world(T0_UTC_S, 3)
    gps = df.copy()
    gps["time"] = df["time"] + 18.0  # GPS - UTC = 18 s in 2022
    with server.client() as c:
        r = c.post(
            "/v1/spacecraft/sat-1/telemetry?time_scale=GPS",
            content=gps.to_csv(index=False),
            headers=CSV,
        )
        assert r.json()["accepted"] == 3
        # the same samples in UTC are recognised as already stored
        r = c.post("/v1/spacecraft/sat-1/telemetry", content=df.to_csv(index=False), headers=CSV)
        assert r.json() == {"accepted": 0, "duplicates": 3, "rejected": []}
        r = c.post(
            "/v1/spacecraft/sat-1/telemetry?time_scale=MARS",
            content=df.to_csv(index=False),
            headers=CSV,
        )
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "query.time_scale"


def test_errors_are_json_naming_the_problem(server: LiveServer) -> None:
    _register(server)
    with server.client() as c:
        r = c.post("/v1/spacecraft/nope/telemetry", content=b"time,b_x\n", headers=CSV)
        assert r.status_code == 404 and "nope" in r.json()["detail"]
        r = c.post("/v1/spacecraft/sat-1/telemetry", content=b"a,b\n1,2\n", headers=CSV)
        assert r.status_code == 400 and "time" in r.json()["detail"]
        r = c.post("/v1/spacecraft/sat-1/telemetry", content=b"x", headers={"content-type": "x/y"})
        assert r.status_code == 415
        r = c.post("/v1/spacecraft", json={"id": "sat-1"})
        assert r.status_code == 409
        r = c.post("/v1/spacecraft", json={"id": "a b", "attitude_frame": "XYZ"})
        assert r.status_code == 422
        fields = {e["field"] for e in r.json()["errors"]}
        assert fields == {"body.id", "body.attitude_frame"}
        assert c.get("/v1/spacecraft/sat-1/calibration").status_code == 404
        assert c.get("/v1/jobs/0123").status_code == 404
        body = ccsds.encode_packets(np.array([T0_UTC_S]), np.zeros((1, 3)))
        r = c.post(
            "/v1/spacecraft/sat-1/telemetry",
            content=body[:-1],
            headers={"content-type": ccsds_type()},
        )
        assert r.json()["rejected"] == [
            {"row": 0, "reason": "truncated packet: 84 of 85 octets (stream ends)"}
        ]


def test_request_size_limit_and_gzip(tmp_path: Path) -> None:
    settings = sqlite_settings(tmp_path, max_body_bytes=20_000)
    with live_server(settings) as server:
        _register(server)
        df, _ = world(T0_UTC_S, 400)
        text = df.to_csv(index=False).encode()
        assert len(text) > 20_000
        with server.client() as c:
            r = c.post("/v1/spacecraft/sat-1/telemetry", content=text, headers=CSV)
            assert r.status_code == 413 and r.json()["detail"]
            # streamed without a length: counted while reading
            r = c.post(
                "/v1/spacecraft/sat-1/telemetry",
                content=iter([text[:15000], text[15000:]]),
                headers=CSV,
            )
            assert r.status_code == 413
            small = df.iloc[:50].to_csv(index=False).encode()
            r = c.post(
                "/v1/spacecraft/sat-1/telemetry",
                content=gzip.compress(small),
                headers={**CSV, "content-encoding": "gzip"},
            )
            assert r.json()["accepted"] == 50
            bomb = gzip.compress(b"0" * 5_000_000)
            r = c.post(
                "/v1/spacecraft/sat-1/telemetry",
                content=bomb,
                headers={**CSV, "content-encoding": "gzip"},
            )
            assert r.status_code == 413
            assert c.get("/v1/spacecraft/sat-1").json()["samples"] == 50


def test_auth_scopes_and_hashed_keys(server: LiveServer, tmp_path: Path) -> None:
    _register(server, "sat-1")
    _register(server, "sat-2")
    with server.client() as admin:
        r = admin.post("/v1/keys", json={"name": "ops", "scopes": ["ingest:sat-1", "read:sat-1"]})
        assert r.status_code == 201
        key = r.json()["key"]
        assert admin.post("/v1/keys", json={"name": "x", "scopes": ["root"]}).status_code == 422
        reader = admin.post("/v1/keys", json={"name": "r", "scopes": ["read:*"]}).json()["key"]
    body = world(T0_UTC_S, 3)[0].to_csv(index=False)
    with server.client(None) as anon:
        assert anon.get("/healthz").json() == {"status": "ok"}
        assert anon.get("/v1/spacecraft").status_code == 401
        assert anon.get("/metrics").status_code == 401
        assert anon.get("/v1/spacecraft", headers={"X-API-Key": "wrong"}).status_code == 401
    with server.client(key) as ops:
        r = ops.post("/v1/spacecraft/sat-1/telemetry", content=body, headers=CSV)
        assert r.status_code == 200
        r = ops.post("/v1/spacecraft/sat-2/telemetry", content=body, headers=CSV)
        assert r.status_code == 403 and "ingest:sat-2" in r.json()["detail"]
        assert [s["id"] for s in ops.get("/v1/spacecraft").json()] == ["sat-1"]
        assert ops.get("/v1/spacecraft/sat-2/calibrations").status_code == 403
        assert ops.post("/v1/keys", json={"name": "y", "scopes": ["admin"]}).status_code == 403
    with server.client(reader) as rd:
        assert len(rd.get("/v1/spacecraft").json()) == 2
        r = rd.post("/v1/spacecraft/sat-1/telemetry", content=body, headers=CSV)
        assert r.status_code == 403
        assert rd.post("/v1/spacecraft/sat-1/calibrations").status_code == 403
    con = sqlite3.connect(tmp_path / "orbitcal.sqlite")
    dump = "\n".join(con.iterdump())
    con.close()
    assert key not in dump and reader not in dump and ADMIN_KEY not in dump
    with server.client() as admin:
        prefix = next(k["prefix"] for k in admin.get("/v1/keys").json() if k["name"] == "ops")
        assert admin.delete(f"/v1/keys/{prefix}").status_code == 204
    with server.client(key) as ops:
        assert ops.get("/v1/spacecraft").status_code == 401


def test_no_auth_only_on_loopback(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="refusing"):
        create_app(sqlite_settings(tmp_path, auth=False, bind_host="0.0.0.0"))
    settings = sqlite_settings(tmp_path, auth=False, bind_host="127.0.0.1")
    with live_server(settings) as server, server.client(None) as c:
        assert c.post("/v1/spacecraft", json={"id": "open"}).status_code == 201


def test_openapi_documents_every_contract_path(server: LiveServer) -> None:
    with server.client(None) as c:
        spec = c.get("/openapi.json").json()
    paths = spec["paths"]
    expected = {
        ("post", "/v1/spacecraft"),
        ("put", "/v1/spacecraft/{spacecraft_id}/orbit"),
        ("post", "/v1/spacecraft/{spacecraft_id}/telemetry"),
        ("post", "/v1/spacecraft/{spacecraft_id}/calibrations"),
        ("get", "/v1/jobs/{job_id}"),
        ("get", "/v1/spacecraft/{spacecraft_id}/calibration"),
        ("get", "/v1/spacecraft/{spacecraft_id}/calibrations"),
        ("get", "/v1/spacecraft/{spacecraft_id}/diagnosis"),
        ("get", "/healthz"),
        ("get", "/metrics"),
    }
    assert expected <= {(m, p) for p, ops in paths.items() for m in ops}
    content = paths["/v1/spacecraft/{spacecraft_id}/telemetry"]["post"]["requestBody"]["content"]
    assert set(content) == {
        "text/csv",
        "application/x-ndjson",
        "application/json",
        "application/vnd.apache.parquet",
        "application/vnd.ccsds.space-packet",
    }


def test_metrics_count_ingest(server: LiveServer) -> None:
    _register(server)
    df, _ = world(T0_UTC_S, 5)
    df.loc[0, "b_x"] = np.nan
    with server.client() as c:
        c.post("/v1/spacecraft/sat-1/telemetry", content=df.to_csv(index=False), headers=CSV)
        c.post("/v1/spacecraft/sat-1/telemetry", content=df.to_csv(index=False), headers=CSV)
        text = c.get("/metrics").text
    assert 'orbitcal_ingest_samples_total{format="csv"} 4.0' in text
    assert 'orbitcal_ingest_duplicates_total{format="csv"} 4.0' in text
    assert 'orbitcal_ingest_rejected_rows_total{format="csv"} 2.0' in text
    assert 'orbitcal_jobs{status="queued"} 0.0' in text
    assert 'orbitcal_samples_stored{spacecraft="sat-1"} 4.0' in text


def test_settings_come_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ORBITCAL_DATABASE_URL", "sqlite:////tmp/x.sqlite")
    monkeypatch.setenv("ORBITCAL_ADMIN_KEY", "k" * 40)
    monkeypatch.setenv("ORBITCAL_CADENCE_S", "60")
    s = Settings()
    assert s.database_url == "sqlite:////tmp/x.sqlite"
    assert s.cadence_s == 60.0
    assert "k" * 40 not in repr(s)
    assert json.dumps(s.model_dump(mode="json")).count("k" * 40) == 0


SWARM_A_OMM = SWARM_A_2022_OMM  # the same element set as service_worlds.SWARM_A_TLE


def test_orbit_is_set_by_tle_or_omm_and_validated(server: LiveServer) -> None:
    from service_worlds import SWARM_A_TLE

    with server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "sat-1", "tle": SWARM_A_TLE}).status_code == 201
        r = c.put("/v1/spacecraft/sat-1/orbit", json={"omm": SWARM_A_OMM})
        assert r.status_code == 200, r.text
        assert r.json()["orbit"] == "omm"
        r = c.put("/v1/spacecraft/sat-1/orbit", json={"tle": SWARM_A_TLE})
        assert r.status_code == 200 and r.json()["orbit"] == "tle"
        bad = SWARM_A_TLE[:-1] + "0"  # wrong checksum on line 2
        r = c.put("/v1/spacecraft/sat-1/orbit", json={"tle": bad})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "tle"
        assert "checksum" in r.json()["detail"].lower()
        r = c.put("/v1/spacecraft/sat-1/orbit", json={"omm": {"EPOCH": "x"}})
        assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("omm.")
        r = c.put("/v1/spacecraft/sat-1/orbit", json={})
        assert r.status_code == 422
        r = c.put("/v1/spacecraft/nope/orbit", json={"tle": SWARM_A_TLE})
        assert r.status_code == 404
        assert c.get("/v1/spacecraft/sat-1").json()["tle"] == SWARM_A_TLE
