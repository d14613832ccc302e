"""The joint-fit design generated a block of samples at a time.

A joint fit of the 12-parameter calibration and ``p - 12`` effect parameters stacks ``3 N`` rows of
``p`` columns (``docs/design.md``; :mod:`orbitcal.diagnose.effects` writes the model). Formed whole,
that matrix and its reweighted copies grow with ``N`` (19 kB per sample at 86,400 samples), so a
week at 1 Hz would not fit in memory. :class:`BlockedDesign` instead builds the rows of
``FIT_BLOCK_SAMPLES`` samples at a time and accumulates what the fit needs from them: the column
scales, the normal equations ``X' W X`` and ``X' W y``, residuals ``y - X theta`` and, for the
few least-squares solves without weights, the triangular factor of a QR decomposition updated
block by block (``[R; X_b] = Q' R'``). Memory is then bounded by the block size; the results equal
those of the dense matrix up to the order of the floating-point sums.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterator, Sequence

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.effects import FIELD_SCALE_NT, DesignBlock, DiagnosisData

__all__ = ["FIT_BLOCK_SAMPLES", "BlockedDesign"]

IntArray = npt.NDArray[np.intp]

#: Samples per block: the rows of one block, ``3 x FIT_BLOCK_SAMPLES x p x 8`` bytes (1.5 MB at
#: p = 24), stay in the cache while their products are formed.
FIT_BLOCK_SAMPLES = 2048


def _effect_scales(data: DiagnosisData, block: DesignBlock, g: FloatArray) -> FloatArray:
    """Scales of one design block's columns, (p,); computed once per block and data set.

    Effect columns are scaled by the part the calibration cannot absorb, so the ridge acts on
    what the data can tell apart (a time offset under a steady spin is mostly absorbed): the root
    mean square of each column after projection on the 12 calibration columns (their orthonormal
    basis, factorised once per data set). A column the calibration absorbs whole (the radial
    gradient of a pure dipole is -3B/r) keeps a floor of 1e-6 of its plain root mean square, so
    that the normal equations stay invertible. A column's scale depends on that column only, so
    it is kept with the block (a frozen dataclass: stored beside its fields) for every fit.
    """
    cache: dict[int, tuple[weakref.ref[DiagnosisData], FloatArray]]
    cache = block.__dict__.setdefault("_scale_cache", {})
    hit = cache.get(id(data))
    if hit is not None and hit[0]() is data:
        return hit[1]
    n_rows = 3 * data.n
    q = g.shape[2]
    q_cal = data.calibration_q
    step = FIT_BLOCK_SAMPLES
    sum_sq = np.zeros(q)
    q_eff = np.zeros((12, q))
    for a in range(0, data.n, step):
        eff = g[a : a + step].reshape(-1, q)
        sum_sq += np.sum(eff**2, axis=0)
        q_eff += q_cal[3 * a : 3 * a + eff.shape[0]].T @ eff
    rest_sq = np.zeros(q)
    for a in range(0, data.n, step):
        eff = g[a : a + step].reshape(-1, q)
        rest_sq += np.sum((eff - q_cal[3 * a : 3 * a + eff.shape[0]] @ q_eff) ** 2, axis=0)
    raw = np.sqrt(sum_sq / n_rows)
    scale = np.maximum(np.sqrt(rest_sq / n_rows), 1e-6 * raw)
    cache[id(data)] = (weakref.ref(data), scale)
    return scale


class BlockedDesign:
    """The unit-scaled design ``X`` (3N, 12 + sum p) of a joint fit, row block by row block.

    Rows are sample-major (sample ``n`` gives rows ``3n .. 3n+2``, one per sensor axis). Columns:
    ``b_ref / FIELD_SCALE_NT`` per axis (9), an offset per axis (3), then each design block's
    regressors. Every column is divided by its scale (:attr:`scale`): its root mean square over
    all samples for the 12 calibration columns, the root mean square of the part the calibration
    columns cannot absorb for the effect columns (floored at 1e-6 of the plain one).

    Parameters
    ----------
    data : DiagnosisData
        All samples.
    blocks : sequence of DesignBlock
        Effect regressors built on the same samples.
    block_samples : int, optional
        Samples per block (default :data:`FIT_BLOCK_SAMPLES`).
    """

    def __init__(
        self,
        data: DiagnosisData,
        blocks: Sequence[DesignBlock],
        *,
        block_samples: int | None = None,
    ) -> None:
        self.data = data
        self.blocks = list(blocks)
        # Each block's regressors once for the fit (a lazily built block would be rebuilt on
        # every access).
        self._g = [bl.g for bl in self.blocks]
        self.p = 12 + sum(len(bl.names) for bl in self.blocks)
        self.block_samples = int(FIT_BLOCK_SAMPLES if block_samples is None else block_samples)
        self.scale = self._column_scales()

    # -- rows --------------------------------------------------------------------------------

    def raw_rows(self, index: IntArray | slice) -> FloatArray:
        """Unscaled rows of the samples ``index``, shape (3 m, p)."""
        b = self.data.b_ref_body_nt[index] / FIELD_SCALE_NT
        m = b.shape[0]
        x = np.empty((m, 3, self.p))
        x[:, :, :12] = 0.0
        for i in range(3):
            x[:, i, 3 * i : 3 * i + 3] = b
            x[:, i, 9 + i] = 1.0
        col = 12
        for g in self._g:
            q = g.shape[2]
            x[:, :, col : col + q] = g[index]
            col += q
        return x.reshape(3 * m, self.p)

    def rows(self, index: IntArray | slice) -> FloatArray:
        """Unit-scaled rows of the samples ``index``, shape (3 m, p)."""
        x = self.raw_rows(index)
        x /= self.scale
        return x

    def chunks(self, index: IntArray) -> Iterator[tuple[IntArray | slice, slice]]:
        """Blocks of the samples ``index`` and the slice of their rows in ``3 index.size`` rows."""
        contiguous = index.size > 0 and int(index[-1]) - int(index[0]) + 1 == index.size
        for start in range(0, index.size, self.block_samples):
            part = index[start : start + self.block_samples]
            rows = slice(3 * start, 3 * start + 3 * part.size)
            # A run of consecutive samples (the training blocks) is read through views.
            yield (slice(int(part[0]), int(part[-1]) + 1) if contiguous else part), rows

    def _column_scales(self) -> FloatArray:
        b = self.data.b_ref_body_nt / FIELD_SCALE_NT
        # The calibration columns: b_j on one axis's rows and zero on the others (its root mean
        # square over the 3N rows), then an offset of 1 on one axis's rows (sqrt(1/3)).
        rms_b = np.sqrt(np.sum(b**2, axis=0) / (3 * self.data.n))
        cal = np.r_[np.tile(rms_b, 3), np.full(3, np.sqrt(1.0 / 3.0))]
        effects = [
            _effect_scales(self.data, bl, g) for bl, g in zip(self.blocks, self._g, strict=True)
        ]
        scale = np.concatenate([cal, *effects])
        scale[scale == 0.0] = 1.0
        return scale

    # -- products ----------------------------------------------------------------------------

    def normal_equations(
        self, index: IntArray, y: FloatArray, w: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``X' W X`` (p, p) and ``X' W y`` (p,) over the rows of the samples ``index``.

        ``y`` and ``w`` have one value per row, ``3 index.size``.
        """
        gram = np.zeros((self.p, self.p))
        rhs = np.zeros(self.p)
        for part, rows in self.chunks(index):
            x = self.rows(part)
            xw = x * w[rows, None]
            gram += x.T @ xw
            rhs += xw.T @ y[rows]
        return gram, rhs

    def residual(self, index: IntArray, y: FloatArray, theta: FloatArray) -> FloatArray:
        """``y - X theta`` over the rows of the samples ``index``, shape (3 index.size,)."""
        out = np.empty(3 * index.size)
        for part, rows in self.chunks(index):
            out[rows] = y[rows] - self.rows(part) @ theta
        return out

    def lstsq(self, index: IntArray, y: FloatArray, w: FloatArray | None = None) -> FloatArray:
        """Least-squares ``theta`` of ``sqrt(w) y ~ sqrt(w) X theta`` over the samples ``index``.

        The triangular factor is updated block by block (a QR of the previous factor stacked on
        the new rows); the small system is then solved as :func:`numpy.linalg.lstsq` would solve
        the whole one (same singular values, same cut-off ``eps x max(rows, p)``).
        """
        r_acc = np.zeros((0, self.p))
        z_acc = np.zeros(0)
        for part, rows in self.chunks(index):
            x = self.rows(part)
            yb = y[rows]
            if w is not None:
                sw = np.sqrt(w[rows])
                x, yb = x * sw[:, None], yb * sw
            q, r_acc = np.linalg.qr(np.vstack([r_acc, x]))
            z_acc = q.T @ np.concatenate([z_acc, yb])
        rcond = np.finfo(float).eps * max(3 * index.size, self.p)
        return np.asarray(np.linalg.lstsq(r_acc, z_acc, rcond=rcond)[0], dtype=float)
