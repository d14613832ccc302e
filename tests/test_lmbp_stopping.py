"""LM-BP training stops when it is done, decides the hidden layer early, and is reproducible.

Regression (issue 15): on every on-orbit world lmbp-hk ran all 200 epochs (the stopping tests
never fired in scaled units), and with torch's default two threads on a busy two-core machine the
weights differed from run to run.
"""

from __future__ import annotations

import numpy as np
import torch

from orbitcal.calibrate import FitData, fit_method
from orbitcal.calibrate.lmbp import STOPPING, LMBPCalibration


def _world(rng: np.random.Generator, n: int, scale_per_degc: float) -> FitData:
    """A sensor with a temperature-driven scale factor (0 for an affine sensor)."""
    phase = np.linspace(0.0, 40.0 * np.pi, n)
    b_ref = np.column_stack(
        [2e4 * np.cos(phase), 2e4 * np.sin(phase), 3e4 * np.cos(0.37 * phase)]
    ) + rng.normal(0.0, 2e3, (n, 3))
    temp_degc = 20.0 + 8.0 * np.sin(0.11 * phase) + rng.normal(0.0, 0.3, n)
    A = np.eye(3) + rng.normal(0.0, 0.01, (3, 3))
    raw = (b_ref @ A.T) * (1.0 + scale_per_degc * (temp_degc - 20.0) ** 2)[:, None]
    raw += np.array([200.0, -100.0, 50.0]) + rng.normal(0.0, 2.0, (n, 3))
    return FitData(raw, b_ref, x_hk=temp_degc[:, None], hk_names=["temperature"])


def _fit(data: FitData, seed: int) -> LMBPCalibration:
    cal = fit_method("lmbp-hk", data, generator=torch.Generator().manual_seed(seed))
    assert isinstance(cal, LMBPCalibration)
    return cal


def test_an_affine_sensor_is_decided_linear_within_a_few_epochs() -> None:
    cal = _fit(_world(np.random.default_rng(1), 4000, 0.0), 0)
    assert str(cal.training["hidden_layer"]).startswith("off")
    assert cal.training["stop_reason"] in {"monitor", "loss"}  # not the epoch cap
    assert int(cal.training["epochs"]) <= 20  # was 200


def test_a_nonlinear_sensor_keeps_the_network_and_stops_before_the_cap() -> None:
    data = _world(np.random.default_rng(2), 4000, 5e-6)
    cal = _fit(data, 0)
    assert str(cal.training["hidden_layer"]).startswith("kept")
    assert cal.training["stop_reason"] in {"loss", "gradient", "step"}
    assert int(cal.training["epochs"]) < STOPPING.max_epochs
    rms_nt = float(
        np.sqrt(np.mean((cal.apply(data.b_raw_nt, data.x_hk) - data.b_ref_body_nt) ** 2))
    )
    lin = fit_method("linear-hk", data, generator=torch.Generator().manual_seed(0))
    rms_lin_nt = float(
        np.sqrt(np.mean((lin.apply(data.b_raw_nt, data.x_hk) - data.b_ref_body_nt) ** 2))
    )
    assert rms_nt < 0.85 * rms_lin_nt  # measured 2.20 nT against 2.76 nT (σ = 2 nT)


def test_same_seed_same_weights_with_two_threads_and_the_count_is_restored() -> None:
    data = _world(np.random.default_rng(3), 3000, 2e-5)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        a, b = _fit(data, 7), _fit(data, 7)
        assert torch.get_num_threads() == 2  # the fit's one thread did not leak out
    finally:
        torch.set_num_threads(before)
    assert np.array_equal(a.params, b.params)
    assert a.training == b.training
