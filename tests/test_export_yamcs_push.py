"""``yamcs-push`` (issue 21) against a Yamcs stand-in on loopback that this test starts: it
implements the two documented endpoints (``POST /api/processors/{instance}/{processor}/
parameters:batchGet`` and ``:batchSet``, yamcs-api ``processing.proto``), checks HTTP Basic
credentials and the payload shape (``NamedObjectId`` + typed ``Value``), and keeps the values it
was given. The values pushed are the new version's coefficients, which compute its calibration
(1e-6 nT through the evaluator the XTCE's JavaScript is tested against)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from export_worlds import EXACT_NT, fitted
from yamcs_standin import PREFIX, FakeYamcs, mdb_of

from orbitcal.export import ExportError, ExportOptions, YamcsTarget, export
from orbitcal.export.product import calibration_form


@pytest.fixture
def docs(swarm_a_temperature_world: Any) -> Iterator[tuple[Any, dict[str, Any]]]:
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    doc2 = json.loads(json.dumps(f.document))
    doc2["version"] = 2
    w = doc2["model"]["weights"]
    w["b2"] = [v + 0.01 for v in w["b2"]]
    yield f, doc2


def _target(url: str, password: str = "s3cret") -> YamcsTarget:
    return YamcsTarget(
        url=url, instance="magsat", processor="realtime", username="ops", password=password
    )


def test_push_sets_every_coefficient_and_the_new_version_computes(
    docs: tuple[Any, dict[str, Any]],
) -> None:
    from orbitcal import pipeline
    from orbitcal.export import evaluate

    f, doc2 = docs
    with FakeYamcs(mdb_of(f.document), user="ops", password="s3cret") as yamcs:
        result = export(doc2, ExportOptions(format="yamcs-push", yamcs=_target(yamcs.url)))
        report = result.report
        assert report is not None
        assert report["previous_version"] == 1 and report["product"]["version"] == 2
        assert report["n_set"] == len(mdb_of(doc2))
        assert yamcs.parameters["/MAGCAL/MAGCAL_VERSION"] == 2
        assert yamcs.parameters["/MAGCAL/MAGCAL_SHA256"] == result.info["document_sha256"]
        # the version is set last: a reader that sees version 2 sees its coefficients
        last = yamcs.requests[-1][1]["request"]
        assert last[-1]["id"]["name"] == "/MAGCAL/MAGCAL_VERSION"
        # what Yamcs now holds computes version 2: the network with the pushed weights
        form = calibration_form(doc2)
        pushed = {k.removeprefix("/MAGCAL/MAGCAL_"): v for k, v in yamcs.parameters.items()}
        coefs = form.coefficients()
        assert all(pushed[k] == v for k, v in coefs.items())
    b_new = pipeline.apply_document(doc2, f.telemetry)
    assert np.max(np.abs(evaluate(form, f.telemetry.b_raw_nt, f.x_hk) - b_new)) < EXACT_NT
    assert np.max(np.abs(b_new - f.b_apply_nt)) > 1.0  # and it is not version 1


def test_push_refuses_an_mdb_of_another_layout(
    docs: tuple[Any, dict[str, Any]], swarm_a_temperature_world: Any
) -> None:
    f, _ = docs
    linear = fitted(swarm_a_temperature_world, "linear-hk").document
    with FakeYamcs(mdb_of(linear), user="ops", password="s3cret") as yamcs:
        before = dict(yamcs.parameters)
        with pytest.raises(ExportError, match="load the new XTCE"):
            export(f.document, ExportOptions(format="yamcs-push", yamcs=_target(yamcs.url)))
        assert yamcs.parameters == before
        assert [p for p, _ in yamcs.requests] == [PREFIX + "batchGet"]


def test_push_reports_refused_credentials_and_no_server(docs: tuple[Any, dict[str, Any]]) -> None:
    f, _ = docs
    with FakeYamcs(mdb_of(f.document), user="ops", password="s3cret") as yamcs:
        with pytest.raises(ExportError, match="answered 401"):
            export(
                f.document,
                ExportOptions(format="yamcs-push", yamcs=_target(yamcs.url, password="wrong")),
            )
        url = yamcs.url
    with pytest.raises(ExportError, match="cannot reach Yamcs"):
        export(
            f.document, ExportOptions(format="yamcs-push", yamcs=replace(_target(url), timeout_s=2))
        )
    with pytest.raises(ExportError, match="needs a Yamcs URL"):
        export(f.document, ExportOptions(format="yamcs-push"))


def test_scheduler_hook_pushes_after_a_promotion(docs: tuple[Any, dict[str, Any]]) -> None:
    from pydantic import SecretStr

    from service.settings import Settings
    from service.yamcs_hook import push_after_promotion

    f, doc2 = docs
    with FakeYamcs(mdb_of(f.document), user="ops", password="s3cret") as yamcs:
        off = Settings(database_url="sqlite://", yamcs_push_url="")
        assert push_after_promotion(off, doc2) is None
        on = Settings(
            database_url="sqlite://",
            yamcs_push_url=yamcs.url,
            yamcs_push_instance="magsat",
            yamcs_push_user="ops",
            yamcs_push_password=SecretStr("s3cret"),
        )
        report = push_after_promotion(on, doc2)
        assert report is not None and report["n_set"] > 0
        assert yamcs.parameters["/MAGCAL/MAGCAL_VERSION"] == 2
        bad = on.model_copy(update={"yamcs_push_password": SecretStr("nope")})
        failed = push_after_promotion(bad, doc2)
        assert failed is not None and "401" in failed["error"]
