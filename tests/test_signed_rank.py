"""The chunk test's signed-rank p-value equals scipy.stats.wilcoxon's (greater, zsplit)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from orbitcal.diagnose.signed_rank import signed_rank_greater_p


def _scipy_p(d: np.ndarray) -> float:
    return float(stats.wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)


@pytest.mark.parametrize("n", [5, 6, 8, 13, 14, 16, 31, 32, 50, 51, 64, 200])
@pytest.mark.parametrize("shift", [-0.5, 0.0, 0.3, 1.0])
def test_continuous_differences(n: int, shift: float) -> None:
    rng = np.random.default_rng(n * 100 + int(10 * shift) + 7)
    for _ in range(20):
        d = rng.normal(shift, 1.0, n)
        assert signed_rank_greater_p(d) == pytest.approx(_scipy_p(d), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("n", [5, 9, 14, 20, 32, 50, 51, 80])
def test_ties_and_zeros(n: int) -> None:
    """Rounded differences (ties) and exact zeros (chunks a local effect does not touch)."""
    rng = np.random.default_rng(n)
    for k in range(30):
        d = np.round(rng.normal(0.2, 1.0, n), 1)
        if k % 3 == 0:
            d[rng.integers(0, n, 2)] = 0.0
        if np.all(d == 0.0):
            continue
        assert signed_rank_greater_p(d) == pytest.approx(_scipy_p(d), rel=1e-12, abs=1e-15)


def test_extremes() -> None:
    for d in (np.arange(1.0, 33.0), -np.arange(1.0, 33.0), np.r_[np.ones(40), -np.ones(40)]):
        assert signed_rank_greater_p(d) == pytest.approx(_scipy_p(d), rel=1e-12, abs=1e-15)
