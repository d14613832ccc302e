"""Wang et al. (2020) eq. 1 sensor model with the paper's eq. 15 and eq. 17 numbers."""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.sensor import SensorModel
from orbitcal.simulate.wang2020 import (
    wang2020_ground,
    wang2020_orbit,
    wang2020_time_s,
    wang2020_truth_nt,
)


def test_eq15_and_eq17_parameters() -> None:
    ground = SensorModel.from_wang2020_ground()
    orbit = SensorModel.wang2020_orbit_change()
    np.testing.assert_array_equal(ground.bias_nt, [-633.2, 1281.7, -455.5])
    np.testing.assert_array_equal(orbit.bias_nt, [-652.7, 1266.4, -444.49])
    np.testing.assert_array_equal(ground.a_matrix[1], [0.0020, 0.9476, -0.0040])
    np.testing.assert_array_equal(orbit.a_matrix[2], [0.0011, 0.0561, 0.9637])
    # eq. 17 changes only the diagonal, each by −0.002
    np.testing.assert_allclose(orbit.a_matrix - ground.a_matrix, -0.002 * np.eye(3), atol=1e-12)
    assert ground.noise_std_nt == orbit.noise_std_nt == 2.0


def test_eq1_by_hand() -> None:
    s = SensorModel.from_wang2020_ground()
    b = np.array([[4000.0, 4100.0, 4000.0]])  # eq. 16 at t = 0
    # A row 1 · b + B0_x = 0.9599·4000 − 0.0209·4100 − 0.0065·4000 − 633.2
    expected_x = 0.9599 * 4000 - 0.0209 * 4100 - 0.0065 * 4000 - 633.2
    assert s.measure_noiseless(b)[0, 0] == pytest.approx(expected_x, abs=1e-9)
    np.testing.assert_allclose(s.invert(s.measure_noiseless(b)), b, atol=1e-9)
    lin = s.linear
    np.testing.assert_allclose(np.array(lin["M"]) @ np.linalg.inv(lin["M"]), np.eye(3), atol=1e-12)
    assert SensorModel.from_dict(s.to_dict()).to_dict() == s.to_dict()


def test_noise_is_seeded_and_has_the_stated_std() -> None:
    s = SensorModel.from_wang2020_ground()
    b = np.full((20000, 3), 4000.0)
    m1 = s.measure(b, rng=np.random.default_rng(7))
    m2 = s.measure(b, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(m1, m2)
    resid = m1 - s.measure_noiseless(b)
    # std of 60 000 draws of σ = 2: 2 ± 0.006 (1σ); 5σ bound
    assert abs(resid.std() - 2.0) < 0.03
    assert abs(resid.mean()) < 0.05


def test_eq16_truth_and_the_scenarios() -> None:
    t = wang2020_time_s()
    assert t[0] == 0.0 and t[-1] < 30.0
    b = wang2020_truth_nt([0.0, np.pi / 2])
    np.testing.assert_allclose(b, [[4000, 4100, 4000], [4100, 4000, 3900]], atol=1e-9)
    g = wang2020_ground(t, rng=np.random.default_rng(0))
    ground = SensorModel.from_wang2020_ground()
    resid = g.b_meas_nt - ground.measure_noiseless(g.b_true_nt)
    assert abs(resid.std() - 2.0) < 0.1 and not g.changed.any()
    o = wang2020_orbit(t, rng=np.random.default_rng(0))
    assert o.changed.sum() == np.sum(t > 15.0)
    after = o.changed
    orbit = SensorModel.wang2020_orbit_change()
    resid_after = o.b_meas_nt[after] - orbit.measure_noiseless(o.b_true_nt[after])
    assert abs(resid_after.std() - 2.0) < 0.1
    # Without recalibration the ground inverse errs after t = 15 s by tens of nT (paper: ~30 nT).
    err = ground.invert(o.b_meas_nt[after]) - o.b_true_nt[after]
    assert 15.0 < np.abs(err).max() < 60.0


def test_random_sensor_is_plausible_and_validated() -> None:
    s = SensorModel.random(rng=np.random.default_rng(3))
    assert np.all(np.abs(np.diag(s.a_matrix) - 1) < 0.2)
    assert np.all(np.abs(s.bias_nt) < 3000)
    with pytest.raises(ValueError, match="singular"):
        SensorModel(a_matrix=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="noise"):
        SensorModel(noise_std_nt=-1.0)


def test_wang2020_change_applied_to_the_ground_sensor_is_eq17() -> None:
    changed = SensorModel.from_wang2020_ground().with_wang2020_change()
    orbit = SensorModel.wang2020_orbit_change()
    np.testing.assert_allclose(changed.a_matrix, orbit.a_matrix, atol=1e-15)
    np.testing.assert_allclose(changed.bias_nt, orbit.bias_nt, atol=1e-9)
