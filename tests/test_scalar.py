"""Attitude-free calibration (TWOSTEP, FLANN of seed 001) on real orbits and on the ground."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from orbitcal.calibrate import FitData, PoorCoverageError, TooFewSamplesError
from orbitcal.calibrate.holdout import later_block_split
from orbitcal.calibrate.scalar import fit_flann, fit_twostep, scalar_residual_nt
from orbitcal.reproduce.onorbit import orbit_world

SIGMA_NT = 5.0


@pytest.mark.parametrize("attitude", ["tumbling", "nadir"])
@pytest.mark.parametrize("fit", [fit_twostep, fit_flann])
def test_scalar_methods_reach_the_noise_floor_on_orbit(attitude: str, fit) -> None:  # type: ignore[no-untyped-def]
    w = orbit_world(
        attitude=attitude, n_samples=2000, noise_std_nt=SIGMA_NT, rng=np.random.default_rng(21)
    )
    mag = np.linalg.norm(w.b_true_body_nt, axis=1)
    data = FitData(w.telemetry.b_raw_nt, None, mag)
    train, hold = later_block_split(w.telemetry.t_utc_s, 0.25)
    cal = fit(data.subset(train))
    r_hold = scalar_residual_nt(cal.apply(data.b_raw_nt[hold]), mag[hold])
    # the noise projected on the field direction has std σ; a few % for the fit
    assert np.sqrt(np.mean(r_hold**2)) < 1.08 * SIGMA_NT
    raw_r = scalar_residual_nt(data.b_raw_nt[hold], mag[hold])
    assert np.sqrt(np.mean(raw_r**2)) > 20 * SIGMA_NT  # there was something to calibrate


def test_flann_c_is_upper_triangular_and_c33_can_be_fixed() -> None:
    w = orbit_world(attitude="tumbling", n_samples=800, rng=np.random.default_rng(22))
    data = FitData(w.telemetry.b_raw_nt, None, np.linalg.norm(w.b_true_body_nt, axis=1))
    cal = fit_flann(data)
    assert np.allclose(np.tril(cal.M, -1), 0.0)
    fixed = fit_flann(data, fix_c33=True)
    assert fixed.M[2, 2] == 1.0 and np.allclose(np.tril(fixed.M, -1), 0.0)


def test_seed_001_ground_case_magnitude_swing_falls_to_the_noise_level() -> None:
    """Wu & Huang (seed 001): a sensor turned in a steady 49 233 nT field, reference = mean |B′|.

    Their swing of the measured magnitude over attitudes fell from 808 nT to 12 nT.
    """
    rng = np.random.default_rng(23)
    n, sigma = 60, 2.0
    b_field = np.array([0.0, 2.0e4, 4.5e4]) * 49233.0 / np.hypot(2.0e4, 4.5e4)
    b_body = Rotation.random(n, random_state=rng.integers(1 << 31)).apply(b_field)
    C = np.array([[1.006, 0.004, -0.003], [0.0, 0.994, 0.005], [0.0, 0.0, 1.0]])
    b0 = np.array([180.0, -120.0, 90.0])
    noise = rng.normal(0.0, sigma, (n, 3))
    raw = b_body @ C.T + b0 + noise
    swing_before = np.ptp(np.linalg.norm(raw, axis=1))
    assert 650.0 < swing_before < 950.0  # the seed's ~800 nT
    cal = fit_flann(FitData(raw, None, None), fix_c33=True)
    swing_after = np.ptp(np.linalg.norm(cal.apply(raw), axis=1))
    swing_noise = np.ptp(np.linalg.norm(b_body + noise, axis=1))  # an ideal sensor's swing
    assert swing_after < 15.0  # the seed: 12 nT
    assert swing_after < 1.5 * swing_noise
    tw = fit_twostep(FitData(raw, None, None))
    assert np.ptp(np.linalg.norm(tw.apply(raw), axis=1)) < 1.5 * swing_noise


def test_scalar_degenerate_inputs() -> None:
    theta = np.linspace(0, 4 * np.pi, 300)
    b = np.column_stack([3e4 * np.cos(theta), 3e4 * np.sin(theta), np.full(300, 2e4)])
    with pytest.raises(PoorCoverageError, match="condition number"):
        fit_twostep(FitData(b, None, np.linalg.norm(b, axis=1)))
    with pytest.raises(TooFewSamplesError):
        fit_flann(FitData(b[:10], None, np.linalg.norm(b[:10], axis=1)))
