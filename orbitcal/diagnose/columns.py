"""Design-block regressors generated for a block of samples at a time.

An effect's regressors ``G`` (N, 3, p) are mostly simple products of per-sample quantities the
diagnosis holds anyway: a housekeeping channel on one sensor axis (two thirds of such a block are
zeros), a body-frame vector times a scalar (the dipole axis times a decay, the magnetic east
direction times a latitude bump, a rotation column times a sinusoid). Held whole, every
candidate's and every variant's block grows with ``N`` (2.4 kB per sample for the eager blocks and
1.5 kB for a field-aligned-current block at 86,400 samples: gigabytes at a week at 1 Hz). The
classes here keep only the factors and build the rows of the samples asked for, so that
:class:`~orbitcal.diagnose.blocked.BlockedDesign` forms its products a block of samples at a time
with memory bounded by the block size. The values are those of the whole array, element by
element (the same operations on the same numbers).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Protocol, TypeAlias

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray

__all__ = [
    "Columns",
    "Factor",
    "FunctionColumns",
    "Index",
    "JoinedColumns",
    "PerAxisColumns",
    "ScaledVectorColumns",
    "chunk_slices",
    "take",
    "triangular_factor",
]

#: Samples asked for: a slice or sample indices.
Index: TypeAlias = slice | npt.NDArray[np.intp]

#: A per-sample quantity: an array over all samples, or a function of the samples asked for.
Factor: TypeAlias = FloatArray | Callable[[Index], FloatArray]

#: Samples per block when a whole block's values are needed in turn (prediction, checks).
CHUNK_SAMPLES = 8192


class Columns(Protocol):
    """Regressors generated on demand: ``columns(index)`` is ``G[index]``, (m, 3, width)."""

    n: int
    width: int

    def __call__(self, index: Index) -> FloatArray: ...


def chunk_slices(n: int, step: int = CHUNK_SAMPLES) -> list[slice]:
    """Consecutive slices of at most ``step`` samples covering ``0 .. n``."""
    return [slice(a, min(a + step, n)) for a in range(0, n, step)]


def triangular_factor(row_blocks: Iterable[FloatArray], width: int) -> FloatArray:
    """The triangular factor ``R`` (width x width) of the rows of ``row_blocks`` stacked,
    ``X = Q R`` (``Q`` not formed): the factor so far stacked on the next block and factorised
    again, so that only one block of rows is held at a time."""
    r = np.zeros((0, width))
    for rows in row_blocks:
        r = np.asarray(np.linalg.qr(np.vstack([r, rows]), mode="r"))  # type: ignore[call-overload]
    return r


def take(factor: Factor, index: Index) -> FloatArray:
    """The values of a per-sample factor at the samples ``index``."""
    return np.asarray(factor(index)) if callable(factor) else factor[index]


class PerAxisColumns:
    """Columns that act on one sensor axis each: ``G[n, i, col(k, i)] = x_k[n]`` (or
    ``x_k[n, i]`` for an (N, 3) factor), zero on the other two axes.

    ``col(k, i) = 3 k + i`` (kind-major: ``x_0`` on x, y, z, then ``x_1`` ...) or, with
    ``axis_major``, ``K i + k`` (axis x's K columns first: a 3 x K coupling matrix row by row).
    """

    def __init__(self, n: int, kinds: Sequence[Factor], *, axis_major: bool = False) -> None:
        self.n = int(n)
        self.kinds = tuple(kinds)
        self.width = 3 * len(self.kinds)
        self.axis_major = axis_major

    def axis_columns(self) -> list[npt.NDArray[np.intp]]:
        """Per sensor axis, the columns that are not zero on that axis's rows."""
        n_kinds = len(self.kinds)
        return [
            np.array(
                [n_kinds * i + k if self.axis_major else 3 * k + i for k in range(n_kinds)],
                dtype=np.intp,
            )
            for i in range(3)
        ]

    def axis_rows(self, index: Index) -> list[FloatArray]:
        """Per sensor axis, the values of :meth:`axis_columns` at the samples ``index``,
        (m, K) each: the block without its zeros."""
        values = [take(x, index) for x in self.kinds]
        m = values[0].shape[0]
        out = []
        for i in range(3):
            a = np.empty((m, len(values)))
            for k, x in enumerate(values):
                a[:, k] = x if x.ndim == 1 else x[:, i]
            out.append(a)
        return out

    def __call__(self, index: Index) -> FloatArray:
        values = [take(x, index) for x in self.kinds]
        m = values[0].shape[0]
        n_kinds = len(values)
        out = np.zeros((m, 3, self.width))
        for k, x in enumerate(values):
            for i in range(3):
                col = n_kinds * i + k if self.axis_major else 3 * k + i
                out[:, i, col] = x if x.ndim == 1 else x[:, i]
        return out


class ScaledVectorColumns:
    """``G[n, :, k] = v_k[n, :] * s_k[n]``: body-frame vectors (N, 3) times scalars (N,), or the
    vector alone where ``s_k`` is None."""

    def __init__(self, n: int, vectors: Sequence[Factor], scalars: Sequence[Factor | None]) -> None:
        if len(vectors) != len(scalars):
            raise ValueError("one scalar (or None) per vector")
        self.n = int(n)
        self.vectors = tuple(vectors)
        self.scalars = tuple(scalars)
        self.width = len(self.vectors)

    def __call__(self, index: Index) -> FloatArray:
        cache: dict[int, FloatArray] = {}

        def values(f: Factor) -> FloatArray:  # each factor once, even if shared by columns
            if id(f) not in cache:
                cache[id(f)] = take(f, index)
            return cache[id(f)]

        first = values(self.vectors[0])
        out = np.empty((first.shape[0], 3, self.width))
        for k, (v, s) in enumerate(zip(self.vectors, self.scalars, strict=True)):
            if s is None:
                out[:, :, k] = values(v)
            else:
                np.multiply(values(v), values(s)[:, None], out=out[:, :, k])
        return out


class FunctionColumns:
    """Columns from a function of the samples asked for, ``fn(index) -> (m, 3, width)``."""

    def __init__(self, n: int, width: int, fn: Callable[[Index], FloatArray]) -> None:
        self.n = int(n)
        self.width = int(width)
        self.fn = fn

    def __call__(self, index: Index) -> FloatArray:
        return np.asarray(self.fn(index))


class JoinedColumns:
    """The columns of several blocks side by side: ``G[index] = [G_1[index] | G_2[index] ...]``
    (each part a function of the samples asked for, e.g. a design block's ``rows``)."""

    def __init__(
        self, n: int, parts: Sequence[Callable[[Index], FloatArray]], widths: Sequence[int]
    ):
        self.n = int(n)
        self.parts = tuple(parts)
        self.width = int(sum(widths))

    def __call__(self, index: Index) -> FloatArray:
        return np.concatenate([part(index) for part in self.parts], axis=2)
