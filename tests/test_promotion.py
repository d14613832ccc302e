"""Promotion against the identity and refusal of undetermined calibrations (issue 24 item 5).

A first calibration (nothing in service, or a champion that cannot be scored) must beat the raw
readings taken as they are on the same held-out rows, and the data must determine it (the raw
readings vary in three directions); a refusal says why, with both figures.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from orbitcal.calibrate.base import AffineCalibration
from orbitcal.calibrate.document import calibration_to_document
from orbitcal.orbit import Orbit
from orbitcal.pipeline import (
    Champion,
    Retraining,
    RetrainOptions,
    decide_promotion,
    fit_document,
    retrain,
)
from orbitcal.pipeline.determination import MAX_CONDITION, undetermined_reason
from orbitcal.reproduce.onorbit import OrbitWorld, orbit_world
from orbitcal.telemetry import Telemetry


@pytest.fixture(scope="module")
def nadir() -> OrbitWorld:
    return orbit_world(attitude="nadir", n_samples=400, rng=np.random.default_rng(3))


def _with_raw(tel: Telemetry, b_raw_nt: np.ndarray) -> Telemetry:
    return dataclasses.replace(tel, b_raw_nt=np.asarray(b_raw_nt, dtype=np.float64))


def _retrain(world: OrbitWorld, tel: Telemetry, **kw: Any) -> Retraining:
    return retrain(
        tel,
        orbit=Orbit.from_tle(world.tle),
        champion=kw.pop("champion", None),
        options=RetrainOptions(method=kw.pop("method", "linear")),
        rng=np.random.default_rng(0),
        **kw,
    )


def test_a_stuck_sensor_first_calibration_is_refused_and_says_why(nadir: OrbitWorld) -> None:
    tel = nadir.telemetry
    stuck = _with_raw(tel, np.repeat(tel.b_raw_nt[:1], len(tel), axis=0))  # 400 identical
    out = _retrain(nadir, stuck)
    p = out.promotion
    print(f"\nstuck sensor: {p.rule}: {p.reason}")
    assert not p.promote and p.rule == "undetermined"
    assert "do not vary" in p.reason and "not put in service" in p.reason
    # both figures are on record; here the constant fit even "beats" the raw readings held out
    # (it outputs the mean field), so only the determination check keeps it out of service
    assert p.identity_rms_nt is not None and p.challenger_rms_nt > 1000.0
    record = out.provenance()
    assert record["comparison"]["rule"] == "undetermined"
    assert record["comparison"]["identity_rms_nt"] == p.identity_rms_nt


def test_a_dead_axis_is_undetermined(nadir: OrbitWorld) -> None:
    b = nadir.telemetry.b_raw_nt.copy()
    b[:, 2] = 1234.5  # the z axis reads one value
    p = _retrain(nadir, _with_raw(nadir.telemetry, b)).promotion
    assert not p.promote and p.rule == "undetermined" and "2 of 3 directions" in p.reason


def test_readings_on_a_line_are_undetermined(nadir: OrbitWorld) -> None:
    s = np.linspace(-1.0, 1.0, len(nadir.telemetry))[:, None]
    b = np.array([20_000.0, -5_000.0, 30_000.0]) + s * np.array([3_000.0, 1_000.0, -2_000.0])
    p = _retrain(nadir, _with_raw(nadir.telemetry, b)).promotion
    assert not p.promote and p.rule == "undetermined" and "1 of 3 directions" in p.reason


def _bad_fit(**_: Any) -> dict[str, Any]:
    """A calibration that doubles the field: determined, worse than none."""
    return calibration_to_document(
        AffineCalibration("linear", 2.0 * np.eye(3), np.zeros(3)),
        spacecraft="",
        version=1,
        reference_field="IGRF-14",
        t_start_utc_s=0.0,
        t_end_utc_s=0.0,
        n_samples=0,
        metrics={"holdout_rms_nt": 0.0},
    )


def test_a_first_calibration_worse_than_none_is_refused(nadir: OrbitWorld) -> None:
    out = _retrain(nadir, nadir.telemetry, fit=lambda tel, **kw: _bad_fit())
    p = out.promotion
    assert not p.promote and p.rule == "identity"
    assert p.identity_rms_nt is not None and p.challenger_rms_nt > 10 * p.identity_rms_nt
    assert "does not beat the uncalibrated readings'" in p.reason


def test_a_sound_first_calibration_beats_the_identity_and_serves(nadir: OrbitWorld) -> None:
    out = _retrain(nadir, nadir.telemetry, fit=fit_document)
    p = out.promotion
    assert p.promote and p.rule == "first calibration"
    assert p.reason.startswith("first calibration of this spacecraft: held-out rms_nt")
    assert p.identity_rms_nt is not None and p.challenger_rms_nt < 0.1 * p.identity_rms_nt
    assert p.champion_rms_nt is None and p.p_value is not None and p.p_value < p.alpha
    prov = out.provenance()
    assert prov["method"] == "linear" and prov["data"]["n"] == 400
    assert prov["comparison"]["holdout_n"] == out.n_holdout and "rows" not in prov


def test_an_unscorable_champion_still_leaves_the_identity_to_beat(nadir: OrbitWorld) -> None:
    champion = _bad_fit()
    champion["model"]["hk_names"] = ["hk_missing"]
    champion["method"] = "linear-hk"
    champion["model"]["K"] = [[0.0], [0.0], [0.0]]
    out = _retrain(
        nadir, nadir.telemetry, fit=lambda tel, **kw: _bad_fit(), champion=Champion(champion, 4)
    )
    assert not out.promotion.promote and out.promotion.rule == "identity"


def test_the_identity_rule_needs_the_margin_and_significance() -> None:
    rng = np.random.default_rng(0)
    same = rng.normal(size=400) ** 2
    p = decide_promotion(same, None, metric="rms_nt", identity_sq_nt2=same * 1.001)
    assert not p.promote and p.rule == "identity" and "needs > 1 %" in p.reason
    # without the identity's residuals (older callers), the old rule: promoted
    assert decide_promotion(same, None, metric="rms_nt").promote


@pytest.mark.parametrize(
    ("b", "words"),
    [
        (np.zeros((0, 3)), "0 samples"),
        (np.ones((3, 3)), "3 samples"),
        (np.full((50, 3), 7.0), "do not vary"),
        (np.c_[np.arange(50.0), np.arange(50.0) ** 2, np.zeros(50)], "2 of 3 directions"),
    ],
)
def test_undetermined_reasons(b: np.ndarray, words: str) -> None:
    why = undetermined_reason(b)
    assert why is not None and words in why


def test_orbit_data_are_determined(nadir: OrbitWorld) -> None:
    assert undetermined_reason(nadir.telemetry.b_raw_nt) is None
    b = nadir.telemetry.b_raw_nt - nadir.telemetry.b_raw_nt.mean(axis=0)
    s = np.linalg.svd(b, compute_uv=False)
    assert s[0] / s[2] < MAX_CONDITION / 1e3  # a nadir orbit is far from the threshold
