"""The LM-BP network: analytic Jacobian, structured normal equations, document round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from orbitcal.calibrate import FitData, PoorCoverageError, TooFewSamplesError, fit_method
from orbitcal.calibrate.document import calibration_from_document, calibration_to_document
from orbitcal.calibrate.lmbp import BPNetwork, LMBPCalibration, NetworkProblem, fit_lmbp


@pytest.mark.parametrize("activation", ["tanh", "sigmoid"])
@pytest.mark.parametrize("linear_path", [False, True])
def test_analytic_jacobian_and_normal_equations_are_exact(
    activation: str, linear_path: bool
) -> None:
    g = torch.Generator().manual_seed(0)
    net = BPNetwork(5, 4, activation, linear_path)  # type: ignore[arg-type]
    w = net.init_params(g)
    u = torch.randn(40, 5, dtype=torch.float64, generator=g)
    t = torch.randn(40, 3, dtype=torch.float64, generator=g)
    prob = NetworkProblem(net, u, t)
    r, J = prob.residuals_and_jacobian(w)
    J_ref = torch.func.jacfwd(prob.residuals)(w)
    torch.testing.assert_close(J, J_ref, rtol=0, atol=1e-13)
    torch.testing.assert_close(r, prob.residuals(w), rtol=0, atol=0)
    r2, JtJ, Jtr = prob.normal_equations(w)
    torch.testing.assert_close(r2, r, rtol=0, atol=0)
    torch.testing.assert_close(JtJ, J_ref.T @ J_ref, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(Jtr, J_ref.T @ r, rtol=1e-12, atol=1e-12)


def _affine_data(rng: np.random.Generator, n: int = 600) -> tuple[FitData, np.ndarray, np.ndarray]:
    b_ref = rng.normal(size=(n, 3))
    b_ref *= (rng.uniform(2e4, 5e4, n) / np.linalg.norm(b_ref, axis=1))[:, None]
    A = np.eye(3) + rng.normal(0, 0.02, (3, 3))
    b0 = rng.normal(0, 300, 3)
    raw = b_ref @ A.T + b0 + rng.normal(0, 2.0, (n, 3))
    return FitData(raw, b_ref), A, b0


def test_linear_path_network_reaches_noise_floor_and_its_linear_block_is_the_sensor() -> None:
    data, A, b0 = _affine_data(np.random.default_rng(5))
    cal = fit_lmbp(data, use_hk=True, generator=torch.Generator().manual_seed(1))
    rms = np.sqrt(np.mean((cal.apply(data.b_raw_nt) - data.b_ref_body_nt) ** 2))
    assert rms < 2.0 * 1.1  # σ = 2 nT through A⁻¹ ≈ I
    M, o = cal.linear()
    np.testing.assert_allclose(M, np.linalg.inv(A), atol=2e-4)
    np.testing.assert_allclose(o, b0, atol=3.0)  # nT


def test_document_round_trip_is_bit_for_bit() -> None:
    rng = np.random.default_rng(6)
    data, _, _ = _affine_data(rng, 300)
    x_hk = rng.normal(20, 5, (300, 1))
    data = FitData(data.b_raw_nt, data.b_ref_body_nt, x_hk=x_hk, hk_names=["temperature"])
    cal = fit_method("lmbp-hk", data, generator=torch.Generator().manual_seed(2), max_epochs=20)
    assert isinstance(cal, LMBPCalibration)
    doc = calibration_to_document(
        cal,
        spacecraft="sc",
        version=3,
        reference_field="IGRF-14",
        t_start_utc_s=0.0,
        t_end_utc_s=10.0,
        n_samples=300,
        metrics={"holdout_rms_nt": 1.0},
    )
    back = calibration_from_document(json.loads(json.dumps(doc)))
    assert np.array_equal(back.apply(data.b_raw_nt, x_hk), cal.apply(data.b_raw_nt, x_hk))
    assert np.array_equal(back.linear()[0], cal.linear()[0])
    assert doc["model"]["inputs"] == ["b_x", "b_y", "b_z", "temperature"]
    assert set(doc["model"]["weights"]) == {"W1", "b1", "W2", "b2", "L"}
    with pytest.raises(ValueError, match="temperature"):
        back.apply(data.b_raw_nt)


def test_too_few_samples_and_warm_start_mismatch_are_rejected() -> None:
    data, _, _ = _affine_data(np.random.default_rng(7), 8)
    with pytest.raises(TooFewSamplesError, match="at least"):
        fit_lmbp(data, n_hidden=3, generator=torch.Generator().manual_seed(0))
    big, _, _ = _affine_data(np.random.default_rng(8), 200)
    cal = fit_lmbp(big, n_hidden=3, generator=torch.Generator().manual_seed(0))
    with pytest.raises(ValueError, match="architecture"):
        fit_lmbp(big, n_hidden=4, generator=torch.Generator().manual_seed(0), warm_start=cal)


def test_on_orbit_variant_drops_constant_housekeeping_and_rejects_poor_coverage() -> None:
    rng = np.random.default_rng(9)
    data, _, _ = _affine_data(rng, 300)
    x_hk = np.column_stack([rng.normal(20, 5, 300), np.ones(300)])  # a flag that never changes
    data = FitData(
        data.b_raw_nt, data.b_ref_body_nt, x_hk=x_hk, hk_names=["temperature", "hk_flag"]
    )
    cal = fit_lmbp(data, use_hk=True, generator=torch.Generator().manual_seed(3))
    assert cal.hk_names == ["temperature"]
    theta = np.linspace(0, 6 * np.pi, 300)
    b_ref = np.column_stack([3e4 * np.cos(theta), 3e4 * np.sin(theta), np.full(300, 2e4)])
    raw = b_ref + rng.normal(0, 5, b_ref.shape)
    raw[:, 2] = 2e4  # the z axis never sees a change: unobservable
    with pytest.raises(PoorCoverageError, match="condition number"):
        fit_lmbp(FitData(raw, b_ref), use_hk=True, generator=torch.Generator().manual_seed(3))
