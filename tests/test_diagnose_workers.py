"""The candidates of a selection step fitted side by side on threads give the very report of
one fitted after the other (issue 25, the day at 1 Hz: :attr:`AttributionOptions.workers`)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.options import DiagnosisOptions


@pytest.mark.parametrize(("effect", "attitude"), [("magnetorquer", "tumbling"), ("none", "nadir")])
def test_threads_do_not_change_the_report(effect: str, attitude: str) -> None:
    data = make_world(effect, seed=5, attitude=attitude).data
    reports = []
    for workers in (1, 2):
        base = DiagnosisOptions()
        options = dataclasses.replace(
            base, attribution=dataclasses.replace(base.attribution, workers=workers)
        )
        diag = diagnose_data(data, options=options, rng=np.random.default_rng(0))
        reports.append(json.dumps(diag.report.to_json(), sort_keys=True))
    assert reports[0] == reports[1]
    assert json.loads(reports[0])["verdict"] == effect
