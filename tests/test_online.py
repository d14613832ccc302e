"""The seed-002 one-sample estimator and periodic sliding-window retraining."""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from orbitcal.calibrate import Calibration, FitData, fit_method
from orbitcal.calibrate.linear import fit_linear
from orbitcal.calibrate.online import OnlineEllipsoid, PeriodicRetrainer, fit_online
from orbitcal.calibrate.scalar import scalar_residual_nt
from orbitcal.reproduce.onorbit import orbit_world


def test_one_sample_estimator_reaches_noise_floor_on_orbit() -> None:
    w = orbit_world(attitude="tumbling", n_samples=1500, rng=np.random.default_rng(31))
    mag = np.linalg.norm(w.b_true_body_nt, axis=1)
    cal = fit_online(FitData(w.telemetry.b_raw_nt, None, mag))
    r = scalar_residual_nt(cal.apply(w.telemetry.b_raw_nt[-400:]), mag[-400:])
    assert np.sqrt(np.mean(r**2)) < 1.1 * w.noise_std_nt
    # patent step 9: A = GᵀG with G upper triangular (Cholesky), b_cal = G (m − X0)
    assert np.allclose(np.tril(cal.M, -1), 0.0)


def test_patent_mode_with_running_mean_reference() -> None:
    rng = np.random.default_rng(32)
    b_field = np.array([1.0e4, 2.0e4, 4.0e4])
    b_body = Rotation.random(3000, random_state=7).apply(b_field)
    A = np.array([[1.03, 0.01, 0.0], [0.01, 0.97, 0.02], [0.0, 0.02, 1.01]])
    raw = b_body @ A.T + np.array([400.0, -300.0, 200.0]) + rng.normal(0, 2.0, (3000, 3))
    est = OnlineEllipsoid(scale_nt=4.6e4)
    for m in raw:
        est.update(m)
    cal = est.calibration()
    mags = np.linalg.norm(cal.apply(raw[-500:]), axis=1)
    # σ = 2 nT; the early running means are noisy references, so within 2σ
    assert np.std(mags) < 4.0  # from ~1100 nT before
    assert np.std(np.linalg.norm(raw, axis=1)) > 300.0


def test_periodic_retraining_recovers_after_a_parameter_change() -> None:
    w = orbit_world(attitude="tumbling", n_samples=3000, rng=np.random.default_rng(33))
    t = w.telemetry.t_utc_s
    raw = w.telemetry.b_raw_nt.copy()
    change = t >= t[1500]
    # the sensor changes half-way (Wang 2020 eq. 17 analogue: bias and scale shift)
    b0_new = w.bias_nt + np.array([-19.5, -15.3, 11.0])
    raw[change] = (
        w.b_true_body_nt[change] @ (w.a_matrix * 0.998).T
        + b0_new
        + np.random.default_rng(34).normal(0, w.noise_std_nt, (int(change.sum()), 3))
    )
    data = FitData(raw, w.b_true_body_nt)
    initial = fit_linear(data.subset(~change))

    def refit(window: FitData, current: Calibration | None) -> Calibration:
        return fit_method(
            "lmbp-hk",
            window,
            generator=torch.Generator().manual_seed(0),
            warm_start=current,
            max_epochs=30,
        )

    window_s, period_s = 3 * 3600.0, 1800.0
    retrainer = PeriodicRetrainer(refit, window_s=window_s, period_s=period_s)
    retrainer.run(t, data, initial=initial, t_first_s=float(t[1500]) + period_s)
    served = retrainer.apply(t, raw, initial=initial)
    stale = initial.apply(raw[change]) - w.b_true_body_nt[change]
    clean = t >= t[1500] + window_s + period_s
    after = served[clean] - w.b_true_body_nt[clean]
    assert np.sqrt(np.mean(stale**2)) > 4 * w.noise_std_nt
    assert np.sqrt(np.mean(after**2)) < 1.1 * w.noise_std_nt
    assert all(ev.n_samples > 100 for ev in retrainer.events)


def test_online_rejects_degenerate_input() -> None:
    import pytest

    from orbitcal.calibrate import PoorCoverageError, TooFewSamplesError

    theta = np.linspace(0, 4 * np.pi, 400)
    b = np.column_stack([3e4 * np.cos(theta), 3e4 * np.sin(theta), np.full(400, 2e4)])
    with pytest.raises(TooFewSamplesError, match="at least 20"):
        fit_online(FitData(b[:5], None, np.linalg.norm(b[:5], axis=1)))
    # a field turning about one axis only: the ellipsoid is not pinned down
    with pytest.raises(PoorCoverageError):
        fit_online(FitData(b + 400.0, None, np.full(400, 3.0e4)))


def test_registry_names_and_public_api() -> None:
    import orbitcal.calibrate as oc

    assert set(oc.METHODS) == {
        "linear",
        "linear-hk",
        "lmbp",
        "lmbp-hk",
        "twostep",
        "flann",
        "online",
    }
    assert {m for m, s in oc.METHODS.items() if not s.vector} == {"twostep", "flann", "online"}
    assert oc.DEFAULT_METHOD in oc.METHODS
    assert all(hasattr(oc, name) for name in oc.__all__)
