"""The joint-fit design generated a block of samples at a time.

A joint fit of the 12-parameter calibration and ``p - 12`` effect parameters stacks ``3 N`` rows of
``p`` columns (``docs/design.md``; :mod:`orbitcal.diagnose.effects` writes the model). Formed whole,
that matrix and its reweighted copies grow with ``N`` (19 kB per sample at 86,400 samples), so a
week at 1 Hz would not fit in memory. :class:`BlockedDesign` instead builds the rows of
``FIT_BLOCK_SAMPLES`` samples at a time and accumulates what the fit needs from them: the column
scales, the normal equations ``X' W X`` and ``X' W y`` and residuals ``y - X theta`` (both from the
design's structure, without forming its rows: :meth:`BlockedDesign.normal_equations`) and, for the
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
from orbitcal.diagnose.calibration_columns import calibration_r_inv, calibration_rows
from orbitcal.diagnose.data import FIELD_SCALE_NT, DiagnosisData
from orbitcal.diagnose.design import DesignBlock

__all__ = [
    "FIT_BLOCK_SAMPLES",
    "FIT_MAX_SAMPLES",
    "BlockedDesign",
    "estimation_samples",
    "estimation_step",
]

IntArray = npt.NDArray[np.intp]

#: Samples per block: the rows of one block, ``3 x FIT_BLOCK_SAMPLES x p x 8`` bytes (1.5 MB at
#: p = 24), stay in the cache while their products are formed.
FIT_BLOCK_SAMPLES = 2048

#: Samples a fit estimates its parameters on at most. Beyond, it uses every k-th of the samples it
#: may see (k = ceil(n / FIT_MAX_SAMPLES)); the residuals, scores and tests that follow read every
#: sample. At 1 Hz a day's 60,480 training samples hold no more about 12 + 20 parameters than
#: every 4th of them (the misfit is correlated over minutes, the noise averages down as 1 / sqrt
#: of 15,000 samples to a hundredth of a nT), and each reweighted fit's passes over them were two
#: thirds of the diagnosis's time on such a day (``benchmarks/diagnose_timing.py``). Every
#: benchmark world (10 s cadence, at most a day) stays below the cap: their fits are unchanged.
FIT_MAX_SAMPLES = 20_000


def estimation_step(n: int) -> int:
    """The k of :func:`estimation_samples` for ``n`` samples: ceil(n / FIT_MAX_SAMPLES), at
    least 1."""
    return max(1, -(-n // FIT_MAX_SAMPLES))


def estimation_samples(fit_mask: npt.NDArray[np.bool_]) -> IntArray:
    """The samples a fit of ``fit_mask`` estimates its parameters on: all of them up to
    :data:`FIT_MAX_SAMPLES`, else every k-th (k = ceil(n / FIT_MAX_SAMPLES))."""
    index = np.flatnonzero(fit_mask)
    step = estimation_step(index.size)
    return index[::step] if step > 1 else index


#: A fit's rows are built once and held for its reweighting steps when they take at most this
#: many bytes (15,000 samples of a 40-column block take 14 MB); beyond, each step builds them
#: again a block at a time.
HELD_ROWS_BYTES = 64 * 2**20

#: Runs of consecutive samples shorter than this on average are read by index, not by views.
MIN_RUN_SAMPLES = 64

#: The columns of the calibration parameters that act on each sensor axis's rows: the matrix row
#: ``a[i, :]`` (columns ``3 i .. 3 i + 2``) and the offset ``o[i]`` (column ``9 + i``).
_CAL_COLUMNS: tuple[list[int], ...] = tuple([3 * i, 3 * i + 1, 3 * i + 2, 9 + i] for i in range(3))


def _effect_scales(data: DiagnosisData, block: DesignBlock) -> FloatArray:
    """Scales of one design block's columns, (p,); computed once per block and data set.

    Effect columns are scaled by the part the calibration cannot absorb, so the ridge acts on
    what the data can tell apart (a time offset under a steady spin is mostly absorbed): the root
    mean square of each column after projection on the 12 calibration columns (their orthonormal
    basis ``X R^-1``, ``R^-1`` computed once per data set). A column the calibration absorbs
    whole (the radial gradient of a pure dipole is -3B/r) keeps a floor of 1e-6 of its plain
    root mean square, so that the normal equations stay invertible. A column's scale depends on
    that column only, so it is kept with the block (a frozen dataclass: stored beside its fields)
    for every fit. Beyond :data:`FIT_MAX_SAMPLES` samples, the root mean squares are read on
    every k-th sample (:func:`estimation_step`), as the fits estimate on.
    """
    cache: dict[int, tuple[weakref.ref[DiagnosisData], FloatArray]]
    cache = block.__dict__.setdefault("_scale_cache", {})
    hit = cache.get(id(data))
    if hit is not None and hit[0]() is data:
        return hit[1]
    q = block.width
    # One pass: the part a column keeps outside the calibration's span has the square norm
    # |e|^2 - |Q^T e|^2 (Q orthonormal), with Q^T e = R^-T X^T e.
    sum_sq = np.zeros(q)
    x_t_eff = np.zeros((12, q))
    # A scale is a root mean square: every k-th sample, as a fit of all samples estimates on
    # (estimation_samples), tells it as well; read as views, FIT_BLOCK_SAMPLES at a time.
    step = estimation_step(data.n)
    span = FIT_BLOCK_SAMPLES * step
    for a in range(0, data.n, span):
        part = slice(a, min(a + span, data.n), step)
        eff = block.rows(part).reshape(-1, q)
        sum_sq += np.sum(eff**2, axis=0)
        x_t_eff += calibration_rows(data, part).T @ eff
    q_eff = calibration_r_inv(data, step).T @ x_t_eff
    n_rows = 3 * len(range(0, data.n, step))
    rest_sq = np.clip(sum_sq - np.sum(q_eff**2, axis=0), 0.0, None)
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
        self.p = 12 + sum(len(bl.names) for bl in self.blocks)
        self.block_samples = int(FIT_BLOCK_SAMPLES if block_samples is None else block_samples)
        self.scale = self._column_scales()
        self._axis_index = self._axis_columns()
        self._held: tuple[IntArray, list[tuple[slice, list[FloatArray]]]] | None = None

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
        for bl in self.blocks:
            q = bl.width
            x[:, :, col : col + q] = bl.rows(index)
            col += q
        return x.reshape(3 * m, self.p)

    def rows(self, index: IntArray | slice) -> FloatArray:
        """Unit-scaled rows of the samples ``index``, shape (3 m, p)."""
        x = self.raw_rows(index)
        x /= self.scale
        return x

    def chunks(self, index: IntArray) -> Iterator[tuple[IntArray | slice, slice]]:
        """Blocks of the samples ``index`` and the slice of their rows in ``3 index.size`` rows.

        Runs of consecutive samples (the training blocks) are cut into blocks of at most
        ``block_samples`` and read through views (a slice); a block never spans two runs. Samples
        mostly apart (runs shorter than :data:`MIN_RUN_SAMPLES` on average, e.g. a thinned
        selection) are read in blocks of ``block_samples`` by index instead.
        """
        if index.size == 0:
            return
        breaks = np.flatnonzero(np.diff(index) != 1) + 1
        if index.size < MIN_RUN_SAMPLES * (breaks.size + 1):
            for start in range(0, index.size, self.block_samples):
                part = index[start : start + self.block_samples]
                yield part, slice(3 * start, 3 * start + 3 * part.size)
            return
        starts = np.r_[0, breaks]
        stops = np.r_[breaks, index.size]
        for lo, hi in zip(starts.tolist(), stops.tolist(), strict=True):
            for start in range(lo, hi, self.block_samples):
                stop = min(start + self.block_samples, hi)
                first = int(index[start])
                yield slice(first, first + stop - start), slice(3 * start, 3 * stop)

    def _column_scales(self) -> FloatArray:
        b = self.data.b_ref_body_nt / FIELD_SCALE_NT
        # The calibration columns: b_j on one axis's rows and zero on the others (its root mean
        # square over the 3N rows), then an offset of 1 on one axis's rows (sqrt(1/3)).
        rms_b = np.sqrt(np.sum(b**2, axis=0) / (3 * self.data.n))
        cal = np.r_[np.tile(rms_b, 3), np.full(3, np.sqrt(1.0 / 3.0))]
        effects = [_effect_scales(self.data, bl) for bl in self.blocks]
        scale = np.concatenate([cal, *effects])
        scale[scale == 0.0] = 1.0
        return scale

    # -- products ----------------------------------------------------------------------------

    def _cal_rows(self, part: IntArray | slice) -> FloatArray:
        """Unscaled calibration rows ``(b / FIELD_SCALE_NT, 1)`` of the samples, shape (m, 4).

        Every axis's four calibration columns hold these values on that axis's rows and zeros on
        the other two, so they are kept once per sample.
        """
        b = self.data.b_ref_body_nt[part]
        c = np.empty((b.shape[0], 4))
        np.multiply(b, 1.0 / FIELD_SCALE_NT, out=c[:, :3])
        c[:, 3] = 1.0
        return c

    def _axis_columns(self) -> list[IntArray]:
        """Per sensor axis, the columns of ``X`` that are not zero on that axis's rows: its four
        calibration columns, then each block's :meth:`DesignBlock.axis_columns`."""
        offsets = np.cumsum([12, *[bl.width for bl in self.blocks]]).tolist()
        per_block = [bl.axis_columns() for bl in self.blocks]
        return [
            np.concatenate(
                [np.array(_CAL_COLUMNS[i])]
                + [lo + cols[i] for lo, cols in zip(offsets, per_block, strict=False)]
            ).astype(np.intp)
            for i in range(3)
        ]

    def _axis_design(self, part: IntArray | slice) -> list[FloatArray]:
        """Per sensor axis, that axis's rows of ``X`` (unscaled) without the columns that are
        zero there, (m, len(_axis_index[i])) each."""
        c = self._cal_rows(part)
        per_block = [bl.axis_rows(part) for bl in self.blocks]
        if not per_block:
            return [c, c, c]
        return [np.concatenate([c, *(rows[i] for rows in per_block)], axis=1) for i in range(3)]

    def _axis_blocks(self, index: IntArray) -> Iterator[tuple[slice, list[FloatArray]]]:
        """:meth:`_axis_design` of each block of :meth:`chunks` with the slice of its rows; held
        for the next call with the same ``index`` (a fit's reweighting steps) when they take at
        most :data:`HELD_ROWS_BYTES`."""
        if self._held is not None and self._held[0] is index:
            yield from self._held[1]
            return
        width = sum(ix.size for ix in self._axis_index)
        if 8 * index.size * width > HELD_ROWS_BYTES:
            for part, rows in self.chunks(index):
                yield rows, self._axis_design(part)
            return
        held = [(rows, self._axis_design(part)) for part, rows in self.chunks(index)]
        self._held = (index, held)
        yield from held

    def normal_equations(
        self, index: IntArray, y: FloatArray, w: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``X' W X`` (p, p) and ``X' W y`` (p,) over the rows of the samples ``index``.

        ``y`` and ``w`` have one value per row, ``3 index.size``. Formed per sensor axis from
        that axis's rows without the columns that are zero on them (the other axes' calibration
        columns, and two thirds of a block that acts on one axis per column), unscaled, then
        added into place and scaled once. The dense rows are never assembled.
        """
        axis_index = self._axis_index
        grams = [np.zeros((ix.size, ix.size)) for ix in axis_index]
        rhss = [np.zeros(ix.size) for ix in axis_index]
        for rows, a_axes in self._axis_blocks(index):
            m = a_axes[0].shape[0]
            wv = w[rows].reshape(m, 3)
            yv = y[rows].reshape(m, 3)
            for i, a in enumerate(a_axes):
                aw = a * wv[:, i, None]
                grams[i] += aw.T @ a
                rhss[i] += aw.T @ yv[:, i]
        gram = np.zeros((self.p, self.p))
        rhs = np.zeros(self.p)
        for ix, g_i, r_i in zip(axis_index, grams, rhss, strict=True):
            gram[np.ix_(ix, ix)] += g_i
            rhs[ix] += r_i
        inv = 1.0 / self.scale
        return gram * np.outer(inv, inv), rhs * inv

    def residual(self, index: IntArray, y: FloatArray, theta: FloatArray) -> FloatArray:
        """``y - X theta`` over the rows of the samples ``index``, shape (3 index.size,)."""
        out = np.empty(3 * index.size)
        raw = theta / self.scale  # the parameters of the unscaled columns
        theta_axes = [raw[ix] for ix in self._axis_index]
        for rows, a_axes in self._axis_blocks(index):
            pred = np.column_stack([a @ t for a, t in zip(a_axes, theta_axes, strict=True)])
            out[rows] = y[rows] - pred.reshape(-1)
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
