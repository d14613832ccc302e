"""Weak auroral currents are not named (issue 25: null worlds with small unmodelled fields,
weak auroral currents among them, must stay quiet), strong ones are. At 16f6f12 both weak
worlds below named their 7.5 nT currents."""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.honesty import WEAK_CURRENTS_NT


@pytest.mark.parametrize("seed", [3, 4])
def test_weak_currents_are_withdrawn_strong_ones_named(seed: int) -> None:
    # make_world's currents peak at 150 nT x magnitude: 0.05 -> 7.5 nT, 1.0 -> 150 nT
    weak = make_world("field_aligned_currents", 0.05, attitude="nadir", seed=seed)
    report = diagnose_data(weak.data, rng=np.random.default_rng(0)).report.to_json()
    fac = next(e for e in report["effects"] if e["name"] == "field_aligned_currents")
    assert not fac["significant"]
    assert report["verdict"] == "none"
    if fac["status"] == "weak":  # detected, then withdrawn with the reason
        assert f"{WEAK_CURRENTS_NT:g} nT" in fac["weak_reason"]
        assert report["honesty"]["weak"] == ["field_aligned_currents"]
    strong = make_world("field_aligned_currents", 1.0, attitude="nadir", seed=seed)
    report = diagnose_data(strong.data, rng=np.random.default_rng(0)).report.to_json()
    assert report["verdict"] == "field_aligned_currents"
    assert report["honesty"]["weak"] == []
