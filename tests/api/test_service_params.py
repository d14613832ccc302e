"""Values stored now and used later (issue 24 item 3): a retraining's parameters and a
spacecraft's schedule are bounded at the door (422 naming the field), resolved once into a typed
:class:`service.params.RetrainParams` stored with the job; and a stuck sensor's first calibration
is refused with its reason in the job result and the version history (issue 24 item 5)."""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sqlalchemy as sa
from pydantic import BaseModel
from service_helpers import LiveServer, live_server, sqlite_settings, wait_job
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

from service.params import RetrainParams, Schedule, StoredParamsError
from service.schemas import RetrainIn, ScheduleIn
from service.settings import Settings


def _bounds(model: type[BaseModel]) -> dict[str, tuple[Any, Any]]:
    """``field -> (lowest, highest)`` allowed by the model's metadata."""
    out = {}
    for name, info in model.model_fields.items():
        lo = hi = None
        for m in info.metadata:
            lo = getattr(m, "ge", None) if getattr(m, "ge", None) is not None else lo
            lo = getattr(m, "gt", None) if getattr(m, "gt", None) is not None else lo
            hi = getattr(m, "le", None) if getattr(m, "le", None) is not None else hi
            hi = getattr(m, "lt", None) if getattr(m, "lt", None) is not None else hi
        out[name] = (lo, hi)
    return out


def _out_of_range(lo: Any, hi: Any, kind: Any) -> list[Any]:
    """Values just outside, far outside and of the wrong kind for one bounded field."""
    values: list[Any] = [hi * 2 if hi else 10**30, 10**30, -1, "1e13", [1], {"a": 1}]
    if kind is float:
        values += [1e13 if hi < 1e13 else 1e300, "NaN", "Infinity"]
    if lo is not None and lo > 0:
        values.append(lo / 2)
    return values


def test_every_stored_numeric_field_is_bounded_on_both_sides() -> None:
    """The class, not the example: every numeric field of every object stored for later."""
    for model in (RetrainIn, ScheduleIn, RetrainParams, Schedule):
        for name, (lo, hi) in _bounds(model).items():
            info = model.model_fields[name]
            if info.annotation in (str, "str", "str | None") or name in ("method", "field"):
                continue
            assert lo is not None and hi is not None, f"{model.__name__}.{name} is unbounded"
            assert hi <= 1e19, f"{model.__name__}.{name}: {hi} does not fit the storage"


def _post_retrain(c: Any, sc: str, body: dict[str, Any]) -> Any:
    return c.post(f"/v1/spacecraft/{sc}/calibrations", json=body)


def test_out_of_range_retrain_parameters_and_schedules_are_422_naming_the_field(
    server: LiveServer,
) -> None:
    table: list[tuple[str, str, Any, int]] = []
    with server.client() as c:
        r = c.post("/v1/spacecraft", json={"id": "sc-1", "tle": SWARM_A_TLE})
        assert r.status_code == 201, r.text
        # the example first: 202 and a job failing with an overflow, before
        r = _post_retrain(c, "sc-1", {"window_s": 1e13})
        assert r.status_code == 422 and "window_s" in r.text, r.text
        r = c.post(
            "/v1/spacecraft",
            json={"id": "sc-2", "tle": SWARM_A_TLE, "schedule": {"window_s": 1e13}},
        )
        assert r.status_code == 422 and "schedule.window_s" in r.text, r.text
        for name, (lo, hi) in _bounds(RetrainIn).items():
            if name == "method":
                continue
            kind = float if name.endswith("_s") else int
            for value in _out_of_range(lo, hi, kind):
                r = _post_retrain(c, "sc-1", {name: value})
                table.append(("retrain", name, value, r.status_code))
                assert r.status_code == 422, (name, value, r.text)
                assert any(e["field"].endswith(name) for e in r.json()["errors"]), r.text
        for k, (name, (lo, hi)) in enumerate(_bounds(ScheduleIn).items()):
            kind = float if name.endswith("_s") else int
            for j, value in enumerate(_out_of_range(lo, hi, kind)):
                body = {"id": f"s-{k}-{j}", "tle": SWARM_A_TLE, "schedule": {name: value}}
                r = c.post("/v1/spacecraft", json=body)
                table.append(("schedule", name, value, r.status_code))
                assert r.status_code == 422, (name, value, r.text)
                assert any(e["field"].endswith(f"schedule.{name}") for e in r.json()["errors"])
        r = _post_retrain(c, "sc-1", {"method": "no-such-method"})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "method"
        # nothing was stored for later: no job, no spacecraft
        assert c.get("/v1/spacecraft/sc-2").status_code == 404
        assert c.get("/v1/spacecraft/sc-1/calibrations").json() == []
        # the bounds themselves are accepted, and stored as the resolved object
        r = c.post(
            "/v1/spacecraft",
            json={
                "id": "sc-3",
                "tle": SWARM_A_TLE,
                "schedule": {"window_s": 315_576_000.0, "cadence_s": 1.0, "min_new_samples": 0},
            },
        )
        assert r.status_code == 201, r.text
        r = _post_retrain(c, "sc-3", {"seed": 2**63 - 1})
        assert r.status_code == 202, r.text
        job = c.get(f"/v1/jobs/{r.json()['job_id']}").json()
    assert job["params"] == {
        "method": "linear",
        "field": "IGRF-14",
        "window_s": 315_576_000.0,
        "holdout_fraction": 0.25,
        "min_samples": 200,
        "seed": 2**63 - 1,
    }
    print("\nsurface   field            value          status")
    for surface, name, value, status in table:
        print(f"{surface:9s} {name:16s} {value!r:14.14s} {status}")


def test_params_resolve_once_request_over_schedule_over_settings() -> None:
    settings = Settings(window_s=3600.0, method="linear", min_samples=50)
    p = RetrainParams.resolve(settings, schedule=Schedule(window_s=7200.0), overrides={"seed": 3})
    assert (p.window_s, p.seed, p.min_samples, p.method) == (7200.0, 3, 50, "linear")
    hourly = Schedule(window_s=7200.0)
    p = RetrainParams.resolve(settings, schedule=hourly, overrides={"window_s": 60})
    assert p.window_s == 60.0
    assert RetrainParams.resolve(settings).window_s == 3600.0
    # a job stored by an older release (keys missing) gets them from the settings, once
    old = RetrainParams.from_stored({"method": "linear", "window_s": None}, settings)
    assert old.window_s == 3600.0 and old.holdout_fraction == settings.holdout_fraction
    # a stored value out of bounds fails the job by name, before anything is read or fitted
    with pytest.raises(StoredParamsError, match="window_s"):
        RetrainParams.from_stored({"window_s": 1e13}, settings)
    # a stored schedule out of bounds falls back to the settings (never every job failing)
    assert Schedule.from_stored({"window_s": 1e13, "cadence_s": 60.0}) == Schedule(cadence_s=60.0)
    assert Schedule.from_stored(None) == Schedule()


def test_a_schedule_stored_before_the_bounds_no_longer_fails_every_job(tmp_path: Path) -> None:
    settings = sqlite_settings(tmp_path, min_samples=100)
    with live_server(settings) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "old", "tle": SWARM_A_TLE}).status_code == 201
        engine = sa.create_engine(settings.database_url)
        with engine.begin() as conn:  # as an older release stored it
            conn.execute(
                sa.text("UPDATE spacecraft SET schedule = :s WHERE id = 'old'"),
                {"s": '{"window_s": 1e13}'},
            )
        engine.dispose()
        df, _ = world(T0_UTC_S, 600)
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        r = c.post(
            "/v1/spacecraft/old/telemetry",
            content=buf.getvalue(),
            headers={"content-type": "application/vnd.apache.parquet"},
        )
        assert r.status_code == 200, r.text
        job = wait_job(c, c.post("/v1/spacecraft/old/calibrations").json()["job_id"])
    assert job["status"] == "succeeded", job
    assert job["params"]["window_s"] == settings.window_s


def test_a_stuck_sensor_first_calibration_is_refused_with_its_reason(server: LiveServer) -> None:
    """Issue 24 item 5: 400 identical samples. The job's answer and the history say why."""
    df, _ = world(T0_UTC_S, 400)
    for axis in ("b_x", "b_y", "b_z"):
        df[axis] = float(df[axis].iloc[0])
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    with server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "stuck", "tle": SWARM_A_TLE}).status_code == 201
        r = c.post(
            "/v1/spacecraft/stuck/telemetry",
            content=buf.getvalue(),
            headers={"content-type": "application/vnd.apache.parquet"},
        )
        assert r.json()["accepted"] == 400, r.text
        job = wait_job(c, c.post("/v1/spacecraft/stuck/calibrations").json()["job_id"])
        served = c.get("/v1/spacecraft/stuck/calibration")
        versions = c.get("/v1/spacecraft/stuck/calibrations").json()
    print(f"\nstuck sensor job result: {job['result']}")
    result = job["result"]
    assert job["status"] == "succeeded" and result["promoted"] is False
    assert result["rule"] == "undetermined" and "do not vary" in result["reason"]
    assert result["identity_rms_nt"] is not None and math.isfinite(result["identity_rms_nt"])
    assert served.status_code == 404  # nothing in service
    assert versions[0]["status"] == "rejected" and versions[0]["reason"] == result["reason"]
    comparison = versions[0]["provenance"]["comparison"]
    assert comparison["rule"] == "undetermined"
    assert comparison["identity_rms_nt"] == result["identity_rms_nt"]
    assert np.isfinite(comparison["challenger_rms_nt"])
