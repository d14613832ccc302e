"""The body rate behind the time-offset template: exact for a steady spin, fourth order where
the rate changes (a spin with a nutation of a couple of minutes, as the independent generator's
tumbling attitude has), and the central chord at the ends of a run and beside a gap."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from orbitcal.diagnose.data import DiagnosisData, log_map


def _data(t_s: np.ndarray, body_to_itrs: Rotation) -> DiagnosisData:
    n = t_s.size
    zeros = np.zeros((n, 3))
    return DiagnosisData(
        t_utc_s=t_s,
        b_raw_nt=zeros,
        b_ref_body_nt=zeros,
        rot_itrs_to_body=body_to_itrs.inv().as_matrix(),
        r_itrs_km=np.tile([7000.0, 0.0, 0.0], (n, 1)),
    )


def _attitude(t_s: np.ndarray, rate_deg_s: float, wobble_period_s: float) -> Rotation:
    axis = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    spin = Rotation.from_rotvec(np.outer(np.radians(rate_deg_s) * t_s, axis))
    wob_axis = np.array([0.8, 0.6, 0.0])
    wob = Rotation.from_rotvec(
        np.outer(np.radians(8.0) * np.sin(2 * np.pi * t_s / wobble_period_s), wob_axis)
    )
    return Rotation.from_euler("xyz", [0.3, 0.2, 0.1]) * spin * wob


def _true_rate(t_s: np.ndarray, rate_deg_s: float, wobble_period_s: float) -> np.ndarray:
    """d R / dt R^T of R = itrs -> body, by a central difference over +-1 ms [rad/s]."""
    h = 1e-3
    plus = _attitude(t_s + h, rate_deg_s, wobble_period_s).inv()
    minus = _attitude(t_s - h, rate_deg_s, wobble_period_s).inv()
    return np.asarray((plus * minus.inv()).as_rotvec() / (2 * h))


def test_a_steady_spin_is_differentiated_exactly() -> None:
    t = np.arange(0.0, 600.0, 10.0)
    w = _data(t, _attitude(t, 2.0, np.inf)).body_rate_itrs_rad_s
    true = _true_rate(t, 2.0, np.inf)
    assert np.allclose(w, true, atol=1e-9)


def test_a_nutating_spin_is_differentiated_to_fourth_order() -> None:
    """2 deg/s with an 8 deg nutation of 150 s at a 10 s cadence: the central chord was off by
    about 1 % of the rate (the time offset 2-3 % off on such worlds), the stencil by < 0.1 %."""
    t = np.arange(0.0, 3000.0, 10.0)
    w = _data(t, _attitude(t, 2.0, 150.0)).body_rate_itrs_rad_s
    true = _true_rate(t, 2.0, 150.0)
    inner = slice(2, -2)
    err = np.linalg.norm(w[inner] - true[inner], axis=1) / np.linalg.norm(true[inner], axis=1)
    assert float(np.sqrt(np.mean(err**2))) < 1e-3
    # the ends keep the chord of the nearest samples (still within a few percent)
    ends = np.linalg.norm(w[:2] - true[:2], axis=1) / np.linalg.norm(true[:2], axis=1)
    assert np.all(ends < 0.1)


def test_uneven_steps_and_gaps_keep_the_chord() -> None:
    t = np.arange(0.0, 3000.0, 10.0)
    t = np.concatenate([t[:100], t[100:] + 500.0])  # a gap: two runs
    t[50] += 3.0  # an uneven step inside the first run
    w = _data(t, _attitude(t, 1.0, 300.0)).body_rate_itrs_rad_s
    true = _true_rate(t, 1.0, 300.0)
    err = np.linalg.norm(w - true, axis=1) / np.linalg.norm(true, axis=1)
    assert np.all(np.isfinite(w)) and np.all(err < 0.05)


def test_the_log_map_agrees_with_scipy_from_zero_to_a_half_turn() -> None:
    """The closed form (small angles, by its series near zero) and the quaternion fall-back
    beyond 2 rad give scipy's rotation vectors to rounding, at every angle a relative rotation
    between samples can have."""
    rng = np.random.default_rng(11)
    for angle_rad in (0.0, 1e-12, 1e-7, 1e-6, 1e-3, 0.3, 1.5, 1.99, 2.01, 3.0, np.pi - 1e-9):
        axes = rng.normal(size=(200, 3))
        rotvec = axes * angle_rad / np.linalg.norm(axes, axis=1, keepdims=True)
        matrices = Rotation.from_rotvec(rotvec).as_matrix()
        got = log_map(matrices)
        want = Rotation.from_matrix(matrices).as_rotvec()
        if angle_rad < np.pi - 1e-6:
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)
        else:  # +-pi: the same rotation either way round
            np.testing.assert_allclose(np.linalg.norm(got, axis=1), np.pi - 1e-9, atol=1e-6)
