"""The one-sided Wilcoxon signed-rank test of the held-out chunk test, without ``scipy.stats``.

The attribution asks many times whether per-chunk log ratios are centred above zero
(:func:`orbitcal.diagnose.attribution._chunk_test`). ``scipy.stats.wilcoxon`` answers it, but
importing ``scipy.stats`` costs 0.4-0.7 s of every diagnosis for this one test. This module
computes the same p-value as ``scipy.stats.wilcoxon(d, alternative="greater",
zero_method="zsplit")`` (scipy 1.17, ``method="auto"``, no continuity correction):

- the exact null distribution of the sum of positive ranks (Wilcoxon 1945) when there are at
  most 50 differences, none zero and no ties;
- otherwise the normal approximation with the tie correction of the variance (zero differences
  split their ranks half to each side), except for 13 or fewer differences with ties or zeros,
  where scipy runs an exact permutation test: that rare case is handed to scipy itself.

``tests/test_signed_rank.py`` checks the equality against scipy on random, tied and zero inputs.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from orbitcal.arrays import FloatArray

__all__ = ["signed_rank_greater_p", "signed_rank_z"]

#: Differences up to which the exact distribution is used (scipy's ``method="auto"``).
EXACT_MAX_N = 50

#: Differences up to which scipy enumerates sign permutations when there are ties or zeros.
PERMUTATION_MAX_N = 13


@lru_cache(maxsize=64)
def _null_pmf(n: int) -> FloatArray:
    """Probability of each sum of positive ranks 0 .. n (n + 1) / 2 under the null, shape (.,)."""
    c = np.ones(1)
    for k in range(1, n + 1):
        prev = c
        c = np.zeros(k * (k + 1) // 2 + 1)
        m = prev.size
        c[:m] = prev * 0.5
        c[-m:] += prev * 0.5
    c.setflags(write=False)
    return c


def _average_ranks(a: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Ranks of ``a`` (1-based, ties share their average rank) and the sizes of the tie groups."""
    order = np.argsort(a, kind="mergesort")
    sorted_a = a[order]
    new_group = np.r_[True, sorted_a[1:] != sorted_a[:-1]]
    group = np.cumsum(new_group) - 1
    starts = np.flatnonzero(new_group)
    sizes = np.diff(np.r_[starts, a.size]).astype(float)
    # the average of ranks start+1 .. start+size
    avg = starts + (sizes + 1.0) / 2.0
    ranks = np.empty(a.size)
    ranks[order] = avg[group]
    return ranks, sizes


def signed_rank_greater_p(d: FloatArray) -> float:
    """p-value that the differences ``d`` are centred above zero (one-sided signed-rank test).

    Parameters
    ----------
    d : ndarray, shape (n,)
        Finite differences (here: per-chunk log ratios of the held-out mean square).

    Returns
    -------
    float
        As ``scipy.stats.wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue``.
    """
    d = np.asarray(d, dtype=float).reshape(-1)
    n = d.size
    if n == 0:
        return float("nan")
    zeros = d == 0.0
    ranks, sizes = _average_ranks(np.abs(d))
    has_ties = bool(np.any(sizes > 1.0))
    r_plus = float(np.sum(ranks[d > 0.0])) + float(np.sum(ranks[zeros])) / 2.0
    if n <= EXACT_MAX_N and not (has_ties or bool(np.any(zeros))):
        pmf = _null_pmf(n)
        k = math.floor(r_plus)
        if k <= n * (n + 1) / 4:
            return float(1.0 - pmf[:k].sum()) if k > 0 else 1.0
        return float(pmf[k:].sum())
    if n <= PERMUTATION_MAX_N:
        from scipy import stats  # a few tied chunks: scipy's permutation test

        return float(stats.wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)
    mean = n * (n + 1.0) * 0.25
    var = n * (n + 1.0) * (2.0 * n + 1.0)
    tie_correct = float(np.sum(sizes**3 - sizes))
    se = math.sqrt((var - tie_correct / 2.0) / 24.0)
    if se == 0.0:
        return float("nan")
    z = (r_plus - mean) / se
    return 0.5 * math.erfc(z / math.sqrt(2.0))


def signed_rank_z(d: FloatArray) -> float:
    """The normal score of the sum of positive ranks of ``d`` (zero differences split, ties
    corrected), as in the normal approximation of :func:`signed_rank_greater_p` [-]; nan when
    there is nothing to rank."""
    d = np.asarray(d, dtype=float).reshape(-1)
    n = d.size
    if n == 0:
        return float("nan")
    ranks, sizes = _average_ranks(np.abs(d))
    r_plus = float(np.sum(ranks[d > 0.0])) + float(np.sum(ranks[d == 0.0])) / 2.0
    var = n * (n + 1.0) * (2.0 * n + 1.0) - float(np.sum(sizes**3 - sizes)) / 2.0
    if var <= 0.0:
        return float("nan")
    return (r_plus - n * (n + 1.0) * 0.25) / math.sqrt(var / 24.0)
