"""The confirmation's test counts the base forecast's own parameter uncertainty (issue 43,
item 4: a forecast comparison whose variance respects what the training span leaves unknown).

Under the base model the final block's forecast error is the noise's innovations plus one draw
of the training span's parameter error along the base model's columns there. The test whitens
both forecasts' errors by that predictive covariance (:func:`predictive_rows`): exactly unit
covariance under the base model; a correction along what the base model's own uncertainty
allows is one draw, not a block of evidence; a correction the base model's columns cannot make
is judged as before.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from orbitcal.diagnose.model.confirm import BaseUncertainty, confirm, predictive_rows
from orbitcal.diagnose.model.noise_model import AxisNoise

WHITE = (AxisNoise("ar", np.zeros(0), 1.0, float("nan")),) * 3
STARTS = np.array([0])


def _smooth_design(m: int) -> np.ndarray:
    """(m, 3, 7): per axis a slope and a curvature over the block (how a calibration matrix
    error extrapolates while the field turns), and a column that whitening made zero (an
    offset under a random-walk noise model)."""
    u = np.linspace(0.0, 1.0, m)
    z = np.zeros((m, 3, 7))
    for i in range(3):
        z[:, i, 2 * i] = u
        z[:, i, 2 * i + 1] = u**2 - u / 2.0
    return z


@pytest.mark.parametrize("m", [1, 5, 40])
def test_predictive_rows_whiten_the_predictive_covariance_to_unit(m: int) -> None:
    """``T (I + Z C Z') T' = I`` for the map ``T`` the rows go through, built column by column;
    with ``C = 0`` or no columns ``T = I``; a zero column changes nothing."""
    rng = np.random.default_rng(m)
    z = rng.normal(size=(m, 3, 5))
    z[:, :, 4] = 0.0
    a = rng.normal(size=(5, 5))
    cov = a @ a.T * 30.0
    basis = np.eye(3 * m).reshape(3 * m, m, 3)
    t = np.stack([predictive_rows(b, z, cov).reshape(-1) for b in basis], axis=1)
    zf = z.reshape(3 * m, -1)
    sigma = np.eye(3 * m) + zf @ cov @ zf.T
    np.testing.assert_allclose(t @ sigma @ t.T, np.eye(3 * m), atol=1e-8)
    np.testing.assert_allclose(t, t.T, atol=1e-10)  # the symmetric root
    w = rng.normal(size=(m, 3))
    np.testing.assert_array_equal(predictive_rows(w, z, np.zeros((5, 5))), w)
    np.testing.assert_array_equal(predictive_rows(w, np.zeros((m, 3, 0)), np.zeros((0, 0))), w)


def test_a_correction_along_the_base_models_uncertainty_is_one_draw_not_evidence() -> None:
    """A final block of 360 samples whose calibration forecast is off by one draw of its
    parameter error (40 nT of deviation per column, as a storm pass's 11 quiet minutes leave the
    matrix) plus unit noise. A candidate that bends the extrapolation by another such draw, half
    its size and unrelated to the error (a stand-in), is closer in about half the blocks; the
    noise alone confirms it in 20 or more of 100 (measured 29); with the base forecast's
    uncertainty counted, in at most 10 (the level is 0.05; measured 5). Against a candidate
    that takes off a field the base model's columns cannot make (a 1.5 nT sinusoid of 20
    periods) the test rejects in every block (its RMS is not always lower: the drift's one draw
    can hide 1.5 nT)."""
    m = 360
    z = _smooth_design(m)
    sd = np.r_[np.full(6, 40.0), 0.0]
    base = BaseUncertainty(z, np.diag(sd**2))
    rng = np.random.default_rng(20261130)
    wave = 1.5 * np.sin(2.0 * np.pi * 20.0 * np.arange(m) / m)[:, None] * np.ones(3)
    stand_in_plain, stand_in, real = 0, 0, 0
    for _ in range(100):
        e_base = z @ rng.normal(scale=sd) + rng.normal(size=(m, 3))
        e_model = e_base - 0.5 * z @ rng.normal(scale=sd)
        stand_in_plain += confirm(e_base, e_model, WHITE, STARTS).passes(0.05)
        stand_in += confirm(e_base, e_model, WHITE, STARTS, base=base).passes(0.05)
        real += confirm(e_base + wave, e_base, WHITE, STARTS, base=base).rejects(0.05)
    assert stand_in_plain >= 20, stand_in_plain
    assert stand_in <= 10, stand_in
    assert real == 100


def test_the_test_keeps_its_level_when_the_base_parameters_are_uncertain() -> None:
    """Under the base model with its parameter error drawn from the covariance it states, and a
    candidate whose forecast is independent noise of the same size as a real effect's, the
    test rejects at 0.05 in 2.5-10 % of 400 blocks (5 % nominal: within 0.5-2x; measured 21)."""
    m = 200
    z = _smooth_design(m)
    cov = np.diag(np.r_[np.full(6, 25.0**2), 0.0])
    base = BaseUncertainty(z, cov)
    rng = np.random.default_rng(43)
    rejected = 0
    for _ in range(400):
        e_base = z @ rng.normal(scale=np.sqrt(np.diag(cov))) + rng.normal(size=(m, 3))
        e_model = e_base - 0.3 * rng.normal(size=(m, 3))
        rejected += confirm(e_base, e_model, WHITE, STARTS, base=base).rejects(0.05)
    assert 10 <= rejected <= 40, rejected


HARNESS = Path(__file__).resolve().parents[1] / "benchmarks" / "independent"


@pytest.mark.usefixtures("single_thread_blas")
@pytest.mark.parametrize("draw", [2, 6])
def test_the_storm_pass_at_nadir_names_no_stand_in(tmp_path: Path, draw: int) -> None:
    """The real Swarm A storm pass at nadir (``benchmarks/independent/real_pass.py``, tuning seed
    6900): on its 11 quiet minutes of training the calibration's matrix is left at hundreds of nT
    of posterior deviation, and a sun-driven field (draw 2, probability 0.93) or a time offset
    (draw 6, 0.62) that bent the extrapolation was confirmed at p 8e-18 and 8e-35 (35.9 -> 29.9,
    34.8 -> 28.1 nT, with 1.3 and 0.9 nT of noise). Counting the calibration's uncertainty on the
    final block, neither is named, and the report is right or honest as the harness judges it:
    nothing but the ring current and the auroral currents is significant."""
    sys.path.insert(0, str(HARNESS))
    try:
        import common
        import real_pass
    finally:
        sys.path.remove(str(HARNESS))
    from orbitcal.diagnose.api import diagnose
    from orbitcal.diagnose.options import DiagnosisOptions, ModelOptions
    from orbitcal.telemetry import read_telemetry

    t, r, b_itrs = real_pass.load_pass()
    rng = np.random.default_rng([6900, draw, True])
    sensor = common.draw_sensor(rng)
    rot = common.nadir_body_to_frame(r, t, rng)
    b_body = rot.inv().apply(b_itrs)
    raw = (
        b_body @ sensor.a.T
        + sensor.offset_nt
        + rng.normal(scale=sensor.noise_nt, size=b_body.shape)
    )
    table = tmp_path / "pass.csv"
    common.write_table(table, t, raw, rot, r)
    tel = read_telemetry(table).telemetry
    options = DiagnosisOptions(attitude_frame="ITRS", model=ModelOptions(engine="model"))
    report = diagnose(tel, orbit=None, options=options).report.to_json()
    judged = real_pass.judge(report)
    assert judged["significant"] == [] and judged["ok_or_explicit"], judged
    assert report["confirmation"]["p_value"] > 0.05
