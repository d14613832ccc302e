"""Calibration health through the real service (issue 47): every upload scored against the
calibration in service, the change rule marks it stale at the upload that holds a sensor change,
says when the change began, a retraining on post-change data only goes into service; the CONTRACT
health route's shape, the /metrics gauges, and no Yamcs push of a stale calibration. SQLite and
PostgreSQL."""

from __future__ import annotations

import io
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pandas as pd
import pytest
from conftest_services import require_service
from pydantic import SecretStr
from service_helpers import (
    ADMIN_KEY,
    live_server,
    pg_schema_url,
    sqlite_settings,
    wait_job,
    wait_versions,
)
from service_worlds import SENSOR_A, SENSOR_B, SWARM_A_TLE, T0_UTC_S, world

from service.settings import Settings
from service.yamcs_hook import push_after_promotion

BATCH = 360  # one hour at 0.1 Hz: the demo's upload
DAY_N = 4320  # half a day of samples for the first calibration
HEALTH_KEYS = {
    "version": int,
    "in_service_since": str,
    "recent_rms_nt": float,
    "noise_nt": float,
    "stale": bool,
    "change_at": (str, type(None)),
    "next_retraining": (str, type(None)),
}


def _upload(c: httpx.Client, df: pd.DataFrame) -> None:
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    r = c.post(
        "/v1/spacecraft/sc/telemetry",
        content=buf.getvalue(),
        headers={"content-type": "application/vnd.apache.parquet"},
    )
    assert r.status_code == 200, r.text


def _utc_s(iso: str) -> float:
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


def _check_shape(h: dict[str, Any]) -> None:
    assert set(h) == set(HEALTH_KEYS)
    for k, types in HEALTH_KEYS.items():
        assert isinstance(h[k], types), (k, h[k])
    for k in ("in_service_since", "change_at", "next_retraining"):
        if h[k] is not None:
            assert h[k].endswith("Z") and _utc_s(h[k]) > 0


def _gauges(c: httpx.Client) -> dict[str, float]:
    out = {}
    for line in c.get("/metrics").text.splitlines():
        if line.startswith("orbitcal_health_") and 'spacecraft="sc"' in line:
            out[line.split("{")[0]] = float(line.rsplit(" ", 1)[1])
    return out


def _scenario(settings: Settings) -> None:
    t0 = T0_UTC_S
    with live_server(settings) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "sc", "tle": SWARM_A_TLE}).status_code == 201
        df, _ = world(t0, DAY_N, sensor=SENSOR_A, seed=1, positions=False)
        _upload(c, df)
        assert c.get("/v1/spacecraft/sc/health").status_code == 404  # no calibration yet
        job = wait_job(c, c.post("/v1/spacecraft/sc/calibrations").json()["job_id"])
        assert job["status"] == "succeeded" and job["result"]["promoted"], job
        h = c.get("/v1/spacecraft/sc/health").json()
        _check_shape(h)
        assert h["version"] == 1 and not h["stale"] and h["change_at"] is None
        # the series starts with the version's own held-out block
        series = c.get("/v1/spacecraft/sc/health/series").json()
        assert [p["kind"] for p in series] == ["holdout"]
        assert series[0]["rms_nt"] == pytest.approx(job["result"]["holdout_rms_nt"], rel=0.02)

        # three more hours of the same sensor: scored, never stale
        t = t0 + 10.0 * DAY_N
        for k in range(3):
            df, _ = world(t, BATCH, sensor=SENSOR_A, seed=10 + k, positions=False)
            _upload(c, df)
            t += 10.0 * BATCH
            h = c.get("/v1/spacecraft/sc/health").json()
            assert not h["stale"], h
            assert h["recent_rms_nt"] < 2 * SENSOR_A.noise_nt
            assert h["noise_nt"] == pytest.approx(SENSOR_A.noise_nt, rel=0.25)
        g = _gauges(c)
        assert g["orbitcal_health_stale"] == 0.0
        assert g["orbitcal_health_recent_rms_nt"] == pytest.approx(h["recent_rms_nt"])
        # an upload with duplicates (read back from the database): only its new rows are scored
        again, _ = world(t - 10.0 * 100, 100 + BATCH, sensor=SENSOR_A, seed=13, positions=False)
        _upload(c, again)
        t += 10.0 * BATCH
        assert not c.get("/v1/spacecraft/sc/health").json()["stale"]
        last = series_of(c)[-1]
        assert last["n"] == BATCH and _utc_s(last["end"]) == pytest.approx(t - 10.0)

        # the sensor changes 130 samples into the next upload
        change_s = t + 10.0 * 130
        a, _ = world(t, 130, sensor=SENSOR_A, seed=20, positions=False)
        b, _ = world(change_s, BATCH - 130, sensor=SENSOR_B, seed=21, positions=False)
        _upload(c, pd.concat([a, b], ignore_index=True))
        t += 10.0 * BATCH
        h = c.get("/v1/spacecraft/sc/health").json()
        _check_shape(h)
        assert h["stale"] and h["version"] == 1, h  # caught by the upload that holds the change
        assert abs(_utc_s(h["change_at"]) - change_s) <= 10.0  # to the sample
        assert h["recent_rms_nt"] > 50 * h["noise_nt"]
        g = _gauges(c)
        assert g["orbitcal_health_stale"] == 1.0 and g["orbitcal_health_cusum"] >= np.log(4.0)
        # 230 post-change samples >= min_samples (200): the retraining was queued at once
        versions = wait_versions(c, "sc", 2)
        v2 = versions[0]
        assert v2["status"] == "in_service", v2
        job2 = c.get(f"/v1/jobs/{v2['job_id']}").json()
        assert job2["trigger"] == "health"
        # fitted on data after the change only
        assert _utc_s(v2["provenance"]["data"]["start"]) >= change_s - 10.0
        assert v2["provenance"]["rows"]["excluded"]["before_change"] > 0
        # the new version's own held-out block opens its series; one more upload: healthy
        df, _ = world(t, BATCH, sensor=SENSOR_B, seed=30, positions=False)
        _upload(c, df)
        h = c.get("/v1/spacecraft/sc/health").json()
        assert h["version"] == 2 and not h["stale"] and h["change_at"] is None, h
        assert h["recent_rms_nt"] < 3 * SENSOR_B.noise_nt
        assert _gauges(c)["orbitcal_health_stale"] == 0.0
        kinds = [(p["version"], p["kind"], p["stale"]) for p in series_of(c)]
        assert kinds[:5] == [(1, "holdout", False)] + [(1, "new", False)] * 4
        assert (1, "new", True) in kinds and kinds[-1] == (2, "new", False)


def series_of(c: httpx.Client) -> list[dict[str, Any]]:
    return c.get("/v1/spacecraft/sc/health/series").json()  # type: ignore[no-any-return]


def test_sensor_change_stale_retrained_on_sqlite(tmp_path: Path) -> None:
    _scenario(sqlite_settings(tmp_path, window_s=2 * 86400.0))


@pytest.mark.services
def test_sensor_change_stale_retrained_on_postgresql(tmp_path: Path) -> None:
    require_service("PostgreSQL", 5432)
    with pg_schema_url() as url:
        _scenario(
            Settings(
                database_url=url,
                admin_key=SecretStr(ADMIN_KEY),
                scheduler=False,
                log_level="WARNING",
                window_s=2 * 86400.0,
            )
        )


def test_a_stale_calibration_is_never_pushed_to_yamcs() -> None:
    settings = Settings(yamcs_push_url="http://127.0.0.1:9/", scheduler=False)
    sent: list[Any] = []

    def transport(*args: Any, **kwargs: Any) -> Any:  # pragma: no cover - must not be called
        sent.append(args)
        raise AssertionError("a stale calibration was pushed")

    out = push_after_promotion(settings, {"version": 3}, transport=transport, stale=True)
    assert out is not None and "stale" in out["skipped"] and not sent


def test_health_before_any_data_is_404_naming_it(tmp_path: Path) -> None:
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "sc", "tle": SWARM_A_TLE}).status_code == 201
        r = c.get("/v1/spacecraft/sc/health")
        assert r.status_code == 404 and "no calibration" in r.text
        assert c.get("/v1/spacecraft/nope/health").status_code == 404
        assert c.get("/v1/spacecraft/sc/health/series").json() == []
