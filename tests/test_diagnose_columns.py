"""Regressors generated a block of samples at a time equal the whole arrays they stand for."""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.diagnose.columns import (
    FunctionColumns,
    Index,
    PerAxisColumns,
    ScaledVectorColumns,
    chunk_slices,
)
from orbitcal.diagnose.effects import DesignBlock
from orbitcal.memory import release_freed_arrays

N = 1000
RNG = np.random.default_rng(5)
X = RNG.normal(size=N)
V = RNG.normal(size=(N, 3))
W = RNG.normal(size=(N, 3))
S = RNG.normal(size=N)
INDEXES = [slice(None), slice(10, 300), np.array([0, 5, 6, 999]), np.arange(0, N, 7)]


def _per_axis_dense(kinds: list[np.ndarray], axis_major: bool) -> np.ndarray:
    g = np.zeros((N, 3, 3 * len(kinds)))
    for k, x in enumerate(kinds):
        for i in range(3):
            col = len(kinds) * i + k if axis_major else 3 * k + i
            g[:, i, col] = x if x.ndim == 1 else x[:, i]
    return g


@pytest.mark.parametrize("axis_major", [False, True])
@pytest.mark.parametrize("index", INDEXES, ids=["all", "slice", "few", "thinned"])
def test_per_axis_columns_equal_the_dense_block(axis_major: bool, index: Index) -> None:
    cols = PerAxisColumns(N, [X, V, lambda ix: S[ix] * 2.0], axis_major=axis_major)
    dense = _per_axis_dense([X, V, S * 2.0], axis_major)
    assert cols.width == 9 and cols.n == N
    np.testing.assert_array_equal(cols(index), dense[index])


@pytest.mark.parametrize("index", INDEXES, ids=["all", "slice", "few", "thinned"])
def test_scaled_vector_columns_equal_the_stacked_products(index: Index) -> None:
    cols = ScaledVectorColumns(N, [V, V, W], [None, S, lambda ix: X[ix]])
    dense = np.stack([V, V * S[:, None], W * X[:, None]], axis=2)
    np.testing.assert_array_equal(cols(index), dense[index])


def test_scaled_vector_columns_need_one_scalar_per_vector() -> None:
    with pytest.raises(ValueError, match="one scalar"):
        ScaledVectorColumns(N, [V, W], [None])


def test_design_block_rows_apply_and_finite_checks_agree_with_the_whole_array() -> None:
    dense = np.stack([V, W * S[:, None]], axis=2)
    lazy = DesignBlock(ScaledVectorColumns(N, [V, W], [None, S]), ["a", "b"])
    eager = DesignBlock(dense, ["a", "b"])
    coef = np.array([0.3, -2.0])
    for block in (lazy, eager):
        assert block.n == N and block.width == 2
        np.testing.assert_array_equal(block.g, dense)
        np.testing.assert_allclose(block.apply(coef), dense @ coef, rtol=0, atol=1e-12)
        assert block.all_finite()
    bad = W.copy()
    bad[777, 1] = np.nan
    assert not DesignBlock(ScaledVectorColumns(N, [V, bad], [None, None]), ["a", "b"]).all_finite()
    fn = FunctionColumns(N, 2, lambda ix: dense[ix])
    np.testing.assert_array_equal(DesignBlock(fn, ["a", "b"]).rows(np.array([3, 1])), dense[[3, 1]])


def test_chunk_slices_cover_every_sample_once() -> None:
    parts = chunk_slices(20_000, 8192)
    assert [(p.start, p.stop) for p in parts] == [(0, 8192), (8192, 16384), (16384, 20000)]
    assert chunk_slices(0) == []


def test_release_freed_arrays_applies_on_glibc() -> None:
    import platform

    applied = release_freed_arrays()
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert applied
