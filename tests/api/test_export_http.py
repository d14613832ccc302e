"""``?format=F`` over HTTP (CONTRACT sections 3 and 7, issue 21): the calibration in service and
any stored version, exported as ``orbitcal export`` does; and the ``yamcs-push`` hook of a real
retraining job, against a Yamcs stand-in on loopback."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

from service_helpers import live_server, sqlite_settings, wait_job
from service_worlds import SENSOR_A, SWARM_A_TLE, T0_UTC_S, document_for, world
from yamcs_standin import FakeYamcs, mdb_of

from orbitcal.export import ExportOptions, document_sha256, export


def test_formats_over_http_and_the_push_after_promotion(tmp_path: Path) -> None:
    oracle = {**document_for(SENSOR_A), "metrics": {"holdout_rms_nt": 0.5}, "version": 0}
    mdb = mdb_of({**oracle, "spacecraft": "swarm-a"})  # an MDB loaded from an earlier export
    with FakeYamcs(mdb, user="ops", password="pw") as yamcs:
        settings = sqlite_settings(
            tmp_path,
            yamcs_push_url=yamcs.url,
            yamcs_push_instance="magsat",
            yamcs_push_user="ops",
            yamcs_push_password="pw",
        )
        with live_server(settings) as server, server.client() as c:
            assert (
                c.post("/v1/spacecraft", json={"id": "swarm-a", "tle": SWARM_A_TLE}).status_code
                == 201
            )
            df, _ = world(T0_UTC_S, 2000)
            r = c.post(
                "/v1/spacecraft/swarm-a/telemetry",
                content=df.to_csv(index=False).encode(),
                headers={"content-type": "text/csv"},
            )
            assert r.status_code == 200, r.text
            job = wait_job(c, c.post("/v1/spacecraft/swarm-a/calibrations").json()["job_id"])
            assert job["status"] == "succeeded", job
            pushed = job["result"]["yamcs_push"]
            assert pushed is not None and "error" not in pushed, pushed
            assert yamcs.parameters["/MAGCAL/MAGCAL_VERSION"] == 1
            doc = c.get("/v1/spacecraft/swarm-a/calibration").json()
            assert yamcs.parameters["/MAGCAL/MAGCAL_SHA256"] == document_sha256(doc)

            answers: dict[str, Any] = {}
            for fmt in ("json", "xtce", "cosmos", "c-header", "polynomial", "yamcs-push"):
                a = c.get(f"/v1/spacecraft/swarm-a/calibration?format={fmt}")
                assert a.status_code == 200, (fmt, a.text)
                assert a.headers["x-orbitcal-document-sha256"] == document_sha256(doc)
                b = c.get(f"/v1/spacecraft/swarm-a/calibrations/1?format={fmt}")
                assert b.status_code == 200 and b.content == a.content, fmt
                answers[fmt] = a
            plain = c.get("/v1/spacecraft/swarm-a/calibrations/1")
            named = c.get(
                "/v1/spacecraft/swarm-a/calibration?format=xtce&raw_names=BX,BY,BZ"
                "&cal_names=CX,CY,CZ"
            )
            errors = [
                c.get("/v1/spacecraft/swarm-a/calibration?format=yaml"),
                c.get("/v1/spacecraft/swarm-a/calibration?format=xtce&raw_names=A,B"),
                c.get("/v1/spacecraft/swarm-a/calibrations/7?format=xtce"),
                server.client(key=None).get("/v1/spacecraft/swarm-a/calibration?format=xtce"),
            ]
    assert json.loads(answers["json"].content) == doc == json.loads(plain.content)
    xtce = export(doc, ExportOptions(format="xtce")).content
    assert answers["xtce"].content == xtce
    assert answers["xtce"].headers["content-type"] == "application/xml"
    assert "attachment" in answers["xtce"].headers["content-disposition"]
    assert b'name="CX_LIN"' in named.content and b'name="BX"' in named.content
    files = zipfile.ZipFile(io.BytesIO(answers["cosmos"].content)).namelist()
    assert "targets/MAGCAL/lib/mag_calibration.py" in files
    assert b"ORBITCAL_MAGCAL_SHA256" in answers["c-header"].content
    assert json.loads(answers["polynomial"].content)["product"]["version"] == 1
    body = json.loads(answers["yamcs-push"].content)
    assert {r["id"]["name"] for r in body["request"]} == set(mdb)
    assert [e.status_code for e in errors] == [422, 422, 404, 401]
    assert "unknown export format 'yaml'" in errors[0].text
