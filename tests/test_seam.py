"""The calibration seam (``orbitcal.pipeline``): the typed run, scoring through the full
calibration, which rows a retraining uses, and the promotion rule."""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.calibrate.base import AffineCalibration
from orbitcal.calibrate.document import calibration_to_document
from orbitcal.metrics import rms_nt
from orbitcal.orbit import Orbit
from orbitcal.pipeline import (
    CalibrationRun,
    calibrate,
    decide_promotion,
    fit_data_for_telemetry,
    gross_outlier_free,
    score,
    training_window,
    usable_rows,
)
from orbitcal.reproduce.onorbit import OrbitWorld, orbit_world
from orbitcal.telemetry import Telemetry

DAY_S = 86400.0
NOW = 1_795_000_000.0  # 2026-11-18


# ---------------------------------------------------------------------------------------------
# The window


def test_a_row_in_the_future_never_defines_the_window() -> None:
    t = np.concatenate([NOW - 3 * DAY_S + 10.0 * np.arange(8640), [5_600_000_000.0]])  # + 2147
    w = training_window(t, window_s=DAY_S, min_samples=200, now_utc_s=NOW)
    assert w.end_utc_s == t[-2] and w.excluded == {"future": 1}
    assert w.n == 8640  # a day at 10 s, the window end inclusive


def test_a_lone_row_after_the_dense_data_is_left_out_and_counted() -> None:
    t = np.concatenate([NOW - 60 * DAY_S + 10.0 * np.arange(2000), [NOW - DAY_S]])
    w = training_window(t, window_s=DAY_S, min_samples=200, now_utc_s=NOW)
    assert w.end_utc_s == t[-2] and w.excluded == {"after_window": 1} and w.n == 2000


def test_rows_far_in_the_past_stay_outside_the_window() -> None:
    t = np.concatenate([[-631_152_000.0], NOW - DAY_S + 10.0 * np.arange(500)])  # 1950 first
    w = training_window(t, window_s=DAY_S, min_samples=200, now_utc_s=NOW)
    assert w.start_utc_s is not None and w.start_utc_s > 0 and w.n == 500 and w.excluded == {}


def test_sparse_data_gives_the_fullest_window_and_says_how_many() -> None:
    t = NOW - 10 * DAY_S + DAY_S * np.array([0.0, 0.1, 0.2, 5.0])
    w = training_window(t, window_s=DAY_S, min_samples=200, now_utc_s=NOW)
    assert w.n == 3 and w.end_utc_s == t[2] and w.excluded == {"after_window": 1}
    empty = training_window(np.array([NOW + DAY_S]), window_s=DAY_S, min_samples=1, now_utc_s=NOW)
    assert empty.end_utc_s is None and empty.n == 0 and empty.excluded == {"future": 1}


def test_rows_without_attitude_leave_vector_fits_only() -> None:
    att = np.array([True, False, True, True])
    pos = np.array([True, True, False, True])
    vec = usable_rows(has_attitude=att, has_position=pos, vector=True, have_orbit=True)
    assert vec.mask.tolist() == [True, False, True, True] and vec.excluded == {"no_attitude": 1}
    sca = usable_rows(has_attitude=att, has_position=pos, vector=False, have_orbit=False)
    assert sca.mask.tolist() == [True, True, False, True] and sca.excluded == {"no_position": 1}


def test_gross_outliers_are_glitches_not_sensor_errors() -> None:
    rng = np.random.default_rng(0)
    b_ref = rng.normal(0.0, 25_000.0, (3000, 3))
    mag = np.linalg.norm(b_ref, axis=1)
    b_raw = b_ref @ np.diag([1.02, 0.98, 1.01]).T + [300.0, -200.0, 150.0]  # a plausible sensor
    b_raw += rng.normal(0.0, 2.0, b_raw.shape)
    assert gross_outlier_free(b_raw, mag).all()
    b_raw[1234] *= 3.0
    keep = gross_outlier_free(b_raw, mag)
    assert np.flatnonzero(~keep).tolist() == [1234]


# ---------------------------------------------------------------------------------------------
# Promotion


def _sq(rms: float, n: int = 4000, seed: int = 0) -> np.ndarray:
    """Per-row squared residuals of a 3-component white residual with this rms [nT²]."""
    r = np.random.default_rng(seed).normal(0.0, 1.0, (n, 3))
    r *= rms / np.sqrt(np.mean(r**2))
    return np.mean(r**2, axis=1)


def test_1947_against_1948_nt_is_not_promoted() -> None:
    champion = _sq(1.948)
    challenger = champion * (1.947 / 1.948) ** 2  # better on every row, by 0.05 %
    p = decide_promotion(challenger, champion, metric="rms_nt", champion_version=3)
    assert not p.promote and p.rule == "margin" and p.p_value is None
    assert p.challenger_rms_nt == pytest.approx(1.947) and p.champion_rms_nt == pytest.approx(1.948)
    assert "does not beat version 3's 1.948 nT" in p.reason and "needs > 1 %" in p.reason


def test_a_real_improvement_is_promoted_with_its_p_value() -> None:
    p = decide_promotion(_sq(2.0, seed=1), _sq(17.0, seed=2), metric="rms_nt", champion_version=1)
    assert p.promote and p.rule == "margin and significance"
    assert p.p_value is not None and p.p_value < 1e-4
    assert p.as_dict()["test"].startswith("one-sided Wilcoxon signed-rank over 16")


def test_a_gain_above_the_margin_but_only_in_one_chunk_is_not_significant() -> None:
    champion = _sq(2.0, seed=3)
    challenger = champion.copy()
    challenger[:250] *= 0.2  # 5 % better overall, all of it in the first of 16 chunks
    p = decide_promotion(challenger, champion, metric="rms_nt")
    assert p.gain is not None and p.gain > 0.01
    assert not p.promote and p.rule == "significance" and p.p_value is not None


def test_first_calibration_and_an_unscorable_champion_are_promoted_saying_so() -> None:
    assert decide_promotion(_sq(2.0), None, metric="rms_nt").rule == "first calibration"
    p = decide_promotion(_sq(2.0), None, metric="rms_nt", champion_problem="needs hk_x")
    assert p.promote and p.rule == "champion cannot be scored" and "needs hk_x" in p.reason


# ---------------------------------------------------------------------------------------------
# The run and scoring through the full calibration


@pytest.fixture(scope="module")
def hk_world() -> OrbitWorld:
    return orbit_world(
        attitude="tumbling",
        n_samples=2000,
        noise_std_nt=2.0,
        temperature=True,
        magnetorquer=True,
        rng=np.random.default_rng(5),
    )


def test_the_run_is_typed_and_its_scores_are_the_documents(hk_world: OrbitWorld) -> None:
    run = calibrate(
        hk_world.telemetry,
        orbit=Orbit.from_tle(hk_world.tle),
        method="linear-hk",
        holdout_fraction=0.25,
        rng=np.random.default_rng(0),
    )
    assert isinstance(run, CalibrationRun)
    assert (
        run.train.sum() == 1500 and run.holdout.sum() == 500 and not (run.train & run.holdout).any()
    )
    assert run.document["metrics"]["holdout_rms_nt"] == run.holdout_scores.rms_nt
    assert run.holdout_scores.n == 500
    again = score(run.document, hk_world.telemetry, run.holdout, orbit=Orbit.from_tle(hk_world.tle))
    assert again.rms_nt == pytest.approx(run.holdout_scores.rms_nt, rel=1e-12)


def test_score_applies_the_full_calibration_not_its_linear_part(hk_world: OrbitWorld) -> None:
    tel = hk_world.telemetry
    run = calibrate(
        tel, orbit=Orbit.from_tle(hk_world.tle), method="linear-hk", rng=np.random.default_rng(0)
    )
    m, o = run.calibration.linear()
    linear_only = calibration_to_document(
        AffineCalibration("linear", m, o),
        spacecraft="",
        version=0,
        reference_field="IGRF-14",
        t_start_utc_s=0.0,
        t_end_utc_s=0.0,
        n_samples=0,
        metrics={"holdout_rms_nt": 0.0},
    )
    truth, _ = fit_data_for_telemetry(tel, orbit=Orbit.from_tle(hk_world.tle))
    full = score(run.document, truth=truth)
    part = score(linear_only, truth=truth)
    assert full.rms_nt is not None and part.rms_nt is not None
    assert full.rms_nt < 3.0 < 2 * full.rms_nt < part.rms_nt  # housekeeping fields left in
    from orbitcal.pipeline import apply_document

    assert full.rms_nt == pytest.approx(
        rms_nt(apply_document(run.document, tel), truth.b_ref_body_nt)
    )
    no_hk = Telemetry(t_utc_s=tel.t_utc_s, b_raw_nt=tel.b_raw_nt, q_wxyz=tel.q_wxyz)
    with pytest.raises(ValueError, match="needs housekeeping columns"):
        score(run.document, no_hk, orbit=Orbit.from_tle(hk_world.tle))


def test_the_options_object_and_keywords_give_the_same_run(hk_world: OrbitWorld) -> None:
    from orbitcal.pipeline import CalibrateOptions

    orbit = Orbit.from_tle(hk_world.tle)
    by_keywords = calibrate(
        hk_world.telemetry,
        orbit=orbit,
        rng=np.random.default_rng(0),
        method="linear-hk",
        holdout_fraction=0.3,
    )
    options = CalibrateOptions(method="linear-hk", holdout_fraction=0.3)
    by_options = calibrate(
        hk_world.telemetry, orbit=orbit, rng=np.random.default_rng(0), options=options
    )
    assert by_options.document["linear"] == by_keywords.document["linear"]
    assert by_options.document["metrics"] == by_keywords.document["metrics"]
    assert CalibrateOptions.from_keywords(method="lmbp", n_hidden=3) == CalibrateOptions(
        method="lmbp", method_options={"n_hidden": 3}
    )
    with pytest.raises(TypeError, match="options or keywords"):
        calibrate(
            hk_world.telemetry,
            orbit=orbit,
            rng=np.random.default_rng(0),
            options=options,
            method="linear",
        )
