"""The generic Levenberg–Marquardt optimiser: convergence, stop reasons, Jacobian paths."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from orbitcal.calibrate.lm import LMOptions, levenberg_marquardt, torch_threads
from orbitcal.calibrate.lmbp import BPNetwork, NetworkProblem


def _exp_problem(rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    x = torch.linspace(0.0, 4.0, 200, dtype=torch.float64)
    truth = np.array([2.5, -1.3, 0.5])
    y = truth[0] * torch.exp(truth[1] * x) + truth[2]
    y = y + torch.from_numpy(rng.normal(0.0, 1e-3, 200))
    return x, y, truth


def test_converges_on_nonlinear_fit_with_forward_mode_jacobian() -> None:
    x, y, truth = _exp_problem(np.random.default_rng(1))

    def residuals(p: torch.Tensor) -> torch.Tensor:
        return p[0] * torch.exp(p[1] * x) + p[2] - y

    res = levenberg_marquardt(residuals, torch.tensor([1.0, -0.5, 0.0]))
    # 1e-3 noise on 200 points: parameters to ~1e-3
    np.testing.assert_allclose(res.params.numpy(), truth, atol=5e-3)
    assert res.stop_reason in {"gradient", "step", "loss"}
    assert 1 <= res.epochs < 100
    assert res.mse == pytest.approx(1e-6, rel=0.3)
    assert res.mse_history[0] > res.mse_history[-1]
    assert len(res.mse_history) == res.epochs + 1


def test_linear_problem_matches_lstsq_in_a_few_epochs() -> None:
    rng = np.random.default_rng(2)
    X = rng.normal(size=(500, 6))
    y = X @ rng.normal(size=6) + rng.normal(0, 0.1, 500)
    Xt, yt = torch.from_numpy(X), torch.from_numpy(y)
    res = levenberg_marquardt(lambda p: Xt @ p - yt, torch.zeros(6))
    ref, *_ = np.linalg.lstsq(X, y, rcond=None)
    np.testing.assert_allclose(res.params.numpy(), ref, atol=1e-8)
    assert res.epochs <= 10


def test_target_and_max_epochs_stop_reasons() -> None:
    x, y, _ = _exp_problem(np.random.default_rng(3))

    def residuals(p: torch.Tensor) -> torch.Tensor:
        return p[0] * torch.exp(p[1] * x) + p[2] - y

    start = torch.tensor([1.0, -0.5, 0.0])
    hit = levenberg_marquardt(residuals, start, options=LMOptions(target_mse=1e-2))
    assert hit.stop_reason == "target" and hit.mse <= 1e-2
    capped = levenberg_marquardt(residuals, start, options=LMOptions(max_epochs=1))
    assert capped.stop_reason == "max_epochs" and capped.epochs == 1


def test_gradient_stop_at_the_optimum() -> None:
    X = torch.eye(3, dtype=torch.float64)
    res = levenberg_marquardt(lambda p: X @ p - 1.0, torch.ones(3))
    assert res.stop_reason == "gradient"
    assert res.epochs == 0


class _Quadratic:
    """A problem object with an analytic Jacobian, counted."""

    def __init__(self) -> None:
        self.calls = 0
        self.a = torch.tensor([3.0, -2.0], dtype=torch.float64)

    def residuals(self, p: torch.Tensor) -> torch.Tensor:
        return torch.stack([p[0] ** 2 - self.a[0] ** 2, p[1] - self.a[1], p[0] * p[1] + 6.0])

    def residuals_and_jacobian(self, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        self.calls += 1
        J = torch.stack(
            [
                torch.stack([2 * p[0], torch.zeros((), dtype=p.dtype)]),
                torch.stack([torch.zeros((), dtype=p.dtype), torch.ones((), dtype=p.dtype)]),
                torch.stack([p[1], p[0]]),
            ]
        )
        return self.residuals(p), J


def test_analytic_jacobian_is_used_and_agrees_with_forward_mode() -> None:
    prob = _Quadratic()
    a = levenberg_marquardt(prob, torch.tensor([1.0, 1.0]))
    b = levenberg_marquardt(prob.residuals, torch.tensor([1.0, 1.0]))
    assert prob.calls == a.epochs + 1 or prob.calls == a.epochs
    np.testing.assert_allclose(a.params.numpy(), [3.0, -2.0], atol=1e-8)
    np.testing.assert_allclose(a.params.numpy(), b.params.numpy(), atol=1e-10)


def test_relative_decrease_over_a_window_stops_a_slow_tail() -> None:
    # a 3-6-3 network on noisy data: the error creeps down for hundreds of epochs
    g = torch.Generator().manual_seed(0)
    net = BPNetwork(3, 6)
    u = torch.rand(400, 3, generator=g, dtype=torch.float64) * 2 - 1
    mix = torch.tensor([[1.0, 0.5, -0.3], [0.2, -1.0, 0.4], [0.3, 0.3, 1.2]], dtype=torch.float64)
    t = torch.tanh(u @ mix) + 0.05 * torch.randn(400, 3, generator=g, dtype=torch.float64)
    prob = NetworkProblem(net, u, t)
    w0 = net.init_params(torch.Generator().manual_seed(1))
    strict = levenberg_marquardt(prob, w0, options=LMOptions(gtol=0.0, xtol=0.0))
    loose = levenberg_marquardt(
        prob, w0, options=LMOptions(ftol=1e-3, ftol_epochs=3, gtol=0.0, xtol=0.0)
    )
    assert strict.stop_reason == "max_epochs" and strict.epochs == 200
    assert loose.stop_reason == "loss" and 3 <= loose.epochs < 50
    assert loose.mse == pytest.approx(strict.mse, rel=0.02)


def test_scale_free_gradient_test_fires_whatever_the_units() -> None:
    # the same linear problem in units 1e-6 apart: the cosine test stops both at the same epoch
    rng = np.random.default_rng(5)
    X = torch.from_numpy(rng.normal(size=(300, 4)))
    y = X @ torch.tensor([1.0, -2.0, 0.5, 3.0], dtype=torch.float64) + 0.01 * torch.from_numpy(
        rng.normal(size=300)
    )
    opts = LMOptions(gtol=1e-8, xtol=0.0, ftol=0.0)
    runs = [
        levenberg_marquardt(lambda p, s=s: s * (X @ p - y), torch.zeros(4), options=opts)
        for s in (1.0, 1e-6)
    ]
    assert [r.stop_reason for r in runs] == ["gradient", "gradient"]
    assert runs[0].epochs == runs[1].epochs < 10


def test_monitor_stops_the_fit_and_torch_threads_restores_the_count() -> None:
    x, y, _ = _exp_problem(np.random.default_rng(6))

    def residuals(p: torch.Tensor) -> torch.Tensor:
        return p[0] * torch.exp(p[1] * x) + p[2] - y

    seen: list[int] = []

    def monitor(epoch: int, w: torch.Tensor, mse: float) -> bool:
        seen.append(epoch)
        return epoch == 2

    res = levenberg_marquardt(residuals, torch.tensor([1.0, -0.5, 0.0]), monitor=monitor)
    assert res.stop_reason == "monitor" and res.epochs == 2 and seen == [1, 2]

    before = torch.get_num_threads()
    other = 1 if before != 1 else 2
    with torch_threads(other):
        assert torch.get_num_threads() == other
    assert torch.get_num_threads() == before
    with torch_threads(None):
        assert torch.get_num_threads() == before
