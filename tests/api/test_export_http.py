"""``?format=F`` over HTTP (CONTRACT sections 3 and 7, issue 21): the calibration in service and
any stored version, exported as ``orbitcal export`` does; the ``yamcs-push`` hook of a real
retraining job, against a Yamcs stand-in on loopback; the dashboard's download buttons."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from cdp import Browser
from service_helpers import ADMIN_KEY, LiveServer, live_server, sqlite_settings, wait_job
from service_worlds import SENSOR_A, SWARM_A_TLE, T0_UTC_S, document_for, world
from yamcs_standin import FakeYamcs, mdb_of

from orbitcal.export import ExportOptions, document_sha256, export


@dataclass
class Served:
    server: LiveServer
    yamcs: FakeYamcs
    mdb: dict[str, Any]
    job: dict[str, Any]
    doc: dict[str, Any]


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """A service whose first retraining is promoted and pushed to the Yamcs stand-in."""
    oracle = {**document_for(SENSOR_A), "metrics": {"holdout_rms_nt": 0.5}, "version": 0}
    mdb = mdb_of({**oracle, "spacecraft": "swarm-a"})  # an MDB loaded from an earlier export
    with FakeYamcs(mdb, user="ops", password="pw") as yamcs:
        settings = sqlite_settings(
            tmp_path_factory.mktemp("export_http"),
            yamcs_push_url=yamcs.url,
            yamcs_push_instance="magsat",
            yamcs_push_user="ops",
            yamcs_push_password="pw",
        )
        with live_server(settings) as server, server.client() as c:
            r = c.post("/v1/spacecraft", json={"id": "swarm-a", "tle": SWARM_A_TLE})
            assert r.status_code == 201
            df, _ = world(T0_UTC_S, 2000)
            r = c.post(
                "/v1/spacecraft/swarm-a/telemetry",
                content=df.to_csv(index=False).encode(),
                headers={"content-type": "text/csv"},
            )
            assert r.status_code == 200, r.text
            job = wait_job(c, c.post("/v1/spacecraft/swarm-a/calibrations").json()["job_id"])
            assert job["status"] == "succeeded", job
            doc = c.get("/v1/spacecraft/swarm-a/calibration").json()
            yield Served(server, yamcs, mdb, job, doc)


def test_promotion_pushes_to_yamcs(served: Served) -> None:
    pushed = served.job["result"]["yamcs_push"]
    assert pushed is not None and "error" not in pushed, pushed
    assert pushed["previous_version"] == 0 and pushed["n_set"] == len(served.mdb)
    assert served.yamcs.parameters["/MAGCAL/MAGCAL_VERSION"] == 1
    assert served.yamcs.parameters["/MAGCAL/MAGCAL_SHA256"] == document_sha256(served.doc)


def test_formats_over_http(served: Served) -> None:
    doc = served.doc
    answers: dict[str, Any] = {}
    with served.server.client() as c:
        c.get("/v1/spacecraft/swarm-a/calibration")  # fills the read cache: the fast path
        for fmt in (
            "json",
            "xtce",
            "yamcs-instance",
            "cosmos",
            "c-header",
            "polynomial",
            "yamcs-push",
        ):
            a = c.get(f"/v1/spacecraft/swarm-a/calibration?format={fmt}")
            assert a.status_code == 200, (fmt, a.text)
            assert a.headers["x-orbitcal-document-sha256"] == document_sha256(doc)
            b = c.get(f"/v1/spacecraft/swarm-a/calibrations/1?format={fmt}")
            assert b.status_code == 200 and b.content == a.content, fmt
            answers[fmt] = a
        plain = c.get("/v1/spacecraft/swarm-a/calibrations/1")
        named = c.get(
            "/v1/spacecraft/swarm-a/calibration?format=xtce&raw_names=BX,BY,BZ&cal_names=CX,CY,CZ"
        )
        errors = [
            c.get("/v1/spacecraft/swarm-a/calibration?format=yaml"),
            c.get("/v1/spacecraft/swarm-a/calibration?format=xtce&raw_names=A,B"),
            c.get("/v1/spacecraft/swarm-a/calibrations/7?format=xtce"),
        ]
    with served.server.client(key=None) as anon:
        errors.append(anon.get("/v1/spacecraft/swarm-a/calibration?format=xtce"))
    assert json.loads(answers["json"].content) == doc == json.loads(plain.content)
    assert answers["xtce"].content == export(doc, ExportOptions(format="xtce")).content
    assert answers["xtce"].headers["content-type"] == "application/xml"
    assert "attachment" in answers["xtce"].headers["content-disposition"]
    assert b'name="CX_LIN"' in named.content and b'name="BX"' in named.content
    # issue 45: the ready Yamcs instance as a zip, its MDB the xtce answer
    instance = zipfile.ZipFile(io.BytesIO(answers["yamcs-instance"].content))
    assert sorted(instance.namelist()) == [
        "README.md", "etc/processor.yaml", "etc/yamcs.magcal.yaml", "etc/yamcs.yaml",
        "mdb/MAGCAL.xml",
    ]  # fmt: skip
    assert instance.read("mdb/MAGCAL.xml") == answers["xtce"].content
    assert answers["yamcs-instance"].headers["content-type"] == "application/zip"
    files = zipfile.ZipFile(io.BytesIO(answers["cosmos"].content)).namelist()
    assert "targets/MAGCAL/lib/mag_calibration.py" in files
    assert b"ORBITCAL_MAGCAL_SHA256" in answers["c-header"].content
    poly = json.loads(answers["polynomial"].content)
    assert poly["product"]["version"] == 1
    # the diagonal's loss is measured on the samples the version's retraining held out: there
    # the whole model gives the document's own held-out RMS
    held = poly["held_out"]
    assert held is not None and "retraining held out" in held["source"], held
    assert held["n_samples"] == doc["metrics"]["n_holdout"]
    assert held["full_rms_nt"] == pytest.approx(doc["metrics"]["holdout_rms_nt"], rel=1e-9)
    assert held["diagonal_rms_nt"] > held["full_rms_nt"]
    body = json.loads(answers["yamcs-push"].content)
    assert {r["id"]["name"] for r in body["request"]} == set(served.mdb)
    assert [e.status_code for e in errors] == [422, 422, 404, 401]
    assert "unknown export format 'yaml'" in errors[0].text


@pytest.mark.browser
def test_dashboard_downloads(served: Served, tmp_path: Path) -> None:
    """The dashboard's buttons fetch the exports with the API key and hand them to the browser."""
    capture = """(async () => {
      let blob = null;
      const original = URL.createObjectURL;
      URL.createObjectURL = x => { blob = x; return original(x); };
      document.querySelector('#cal-downloads button[data-format="FMT"]').click();
      for (let i = 0; i < 200 && !blob; i++) await new Promise(r => setTimeout(r, 50));
      URL.createObjectURL = original;
      return blob ? await blob.text() : null;
    })()"""
    with Browser() as browser:
        browser.navigate(served.server.url + "/dashboard")
        assert browser.wait_for("document.body.dataset.ready") == "needs-key"
        browser.evaluate(f"localStorage.setItem('orbitcal.apiKey', {json.dumps(ADMIN_KEY)})")
        browser.navigate(served.server.url + "/dashboard#sc=swarm-a")  # a hash change: no reload
        assert browser.wait_for("document.body.dataset.ready === 'swarm-a'")
        formats = browser.evaluate(
            "[...document.querySelectorAll('#cal-downloads button')].map(b => b.dataset.format)"
        )
        xtce = browser.evaluate(capture.replace("FMT", "xtce"))
        header = browser.evaluate(capture.replace("FMT", "c-header"))
    assert formats == ["json", "xtce", "cosmos", "c-header", "polynomial", "yamcs-push"]
    assert xtce == export(served.doc, ExportOptions(format="xtce")).body().decode()
    assert header == export(served.doc, ExportOptions(format="c-header")).body().decode()
