"""Quiet-time retraining: with a Dst threshold set, the job leaves the storm-time rows out and its
result records how many and which windows (issue 12). The shipped RC index stands in for Dst."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from service_helpers import live_server, sqlite_settings, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

from orbitcal import auxdata

N = 4320  # 12 h at 0.1 Hz


def test_retraining_leaves_storm_time_rows_out_and_says_which(tmp_path: Path) -> None:
    df, _ = world(T0_UTC_S, N, positions=False)
    t = df["time"].to_numpy()
    rc = auxdata.active_table("rc_index")
    assert rc is not None and rc.origin == "shipped"
    d = rc.parsed.data
    mjd = (t - 946_684_800.0) / 86_400.0
    rc_nt = np.interp(mjd, d["time_mjd2000"], d["rc_e_nt"]) + np.interp(
        mjd, d["time_mjd2000"], d["rc_i_nt"]
    )
    threshold = float(np.percentile(rc_nt, 30))  # ~30 % of the rows are "storm time"
    expected = int(np.count_nonzero(rc_nt < threshold))
    assert 0.2 * N < expected < 0.4 * N
    settings = sqlite_settings(tmp_path, quiet_dst_min_nt=threshold)
    with live_server(settings) as server, server.client() as c:
        assert (
            c.post("/v1/spacecraft", json={"id": "swarm-a", "tle": SWARM_A_TLE}).status_code == 201
        )
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        r = c.post(
            "/v1/spacecraft/swarm-a/telemetry",
            content=buf.getvalue(),
            headers={"content-type": "application/vnd.apache.parquet"},
        )
        assert r.json()["accepted"] == N
        job = wait_job(c, c.post("/v1/spacecraft/swarm-a/calibrations").json()["job_id"])
    assert job["status"] == "succeeded", job
    rows = job["result"]["rows"]
    assert rows["excluded"]["storm"] == expected
    assert rows["used"] == N - expected
    quiet = rows["quiet_time"]
    assert quiet["applied"] is True and quiet["left_out"] == expected
    assert quiet["thresholds"] == {"kp_max": None, "dst_min_nt": threshold}
    assert "RC index as a Dst-like stand-in" in quiet["sources"]["dst"]
    assert sum(w["n"] for w in quiet["windows"]) == expected


def test_quiet_time_is_off_by_default(tmp_path: Path) -> None:
    df, _ = world(T0_UTC_S, 600, positions=False)
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        c.post("/v1/spacecraft", json={"id": "sc", "tle": SWARM_A_TLE})
        c.post("/v1/spacecraft/sc/telemetry", content=df.to_csv(index=False).encode(),
               headers={"content-type": "text/csv"})  # fmt: skip
        job = wait_job(c, c.post("/v1/spacecraft/sc/calibrations").json()["job_id"])
    assert job["status"] == "succeeded", job
    assert "storm" not in job["result"]["rows"]["excluded"]
    assert job["result"]["rows"]["quiet_time"] is None
