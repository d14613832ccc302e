"""The model core's columns and their one whitened Gram matrix.

Every candidate effect is a *group* of columns (its design block, :mod:`orbitcal.diagnose.design`)
with a Gaussian prior on its parameters taken from the catalogue's ranges (:func:`group_prior`).
The 12 calibration parameters are the columns ``b_ref / FIELD_SCALE_NT`` and ``1`` of each sensor
axis. With a noise model per axis (:mod:`orbitcal.diagnose.model.noise_model`), the design and the
measurement are whitened axis by axis along time and their cross-products summed into one Gram
matrix ``[X_cal | X_effects | y]' [X_cal | X_effects | y]`` a block of samples at a time (the
rows are never held whole), from which every model's evidence follows
(:mod:`orbitcal.diagnose.model.evidence`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg.blas import dsyrk

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.data import FIELD_SCALE_NT, DiagnosisData
from orbitcal.diagnose.design import DesignBlock
from orbitcal.diagnose.effects import ParamRange, block_ranges
from orbitcal.diagnose.model.noise_model import AxisNoise, whiten_with

__all__ = [
    "CHUNK_SAMPLES",
    "Form",
    "Gram",
    "apply_model",
    "design_rows",
    "group_prior",
    "ranges_prior",
    "whitened_gram",
    "whitened_grams",
]

IntArray = np.ndarray

#: Samples whose rows are built at once.
CHUNK_SAMPLES = 2048

#: A parameter without a finite range gets the prior width that makes its column's field this
#: large [nT] (none of the catalogue's parameters is without one).
UNBOUNDED_FIELD_NT = 100.0


@dataclass(frozen=True)
class Form:
    """One form of one effect: its block, where its columns sit, and its prior.

    Attributes
    ----------
    effect : str
        The catalogue effect.
    block : DesignBlock
        Its regressors.
    cols : slice
        Its columns among the effect columns of the Gram matrix.
    prior_mean, prior_sd : ndarray, shape (p,)
        The Gaussian prior of its parameters, in their units.
    n_forms : int
        How many forms its effect offered (the choice among them is paid for, ``evidence``).
    """

    effect: str
    block: DesignBlock
    cols: slice
    prior_mean: FloatArray
    prior_sd: FloatArray
    n_forms: int


def group_prior(block: DesignBlock, sd_fraction: float) -> tuple[FloatArray, FloatArray]:
    """The Gaussian prior of a block's parameters from its effect's ranges.

    A range with a stated Gaussian prior (a published model's amplitude near 1) gives it;
    otherwise the prior is centred on zero (no effect) when zero is in the range, else on the
    range's middle, with a standard deviation of ``sd_fraction`` times the largest distance
    from that centre to a bound (1/3: the range is three standard deviations).
    """
    return ranges_prior(block_ranges(block), sd_fraction)


def ranges_prior(ranges: Sequence[ParamRange], sd_fraction: float) -> tuple[FloatArray, FloatArray]:
    """The Gaussian prior of parameters of these ranges (:func:`group_prior`)."""
    means, sds = [], []
    for rng in ranges:
        if rng.prior_sd is not None:
            means.append(float(rng.prior_mean or 0.0))
            sds.append(float(rng.prior_sd))
            continue
        lo, hi = float(rng.lower), float(rng.upper)
        centre = 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
        half = max(abs(hi - centre), abs(centre - lo))
        means.append(centre if math.isfinite(centre) else 0.0)
        sds.append(sd_fraction * half if math.isfinite(half) else math.nan)
    return np.array(means), np.array(sds)


@dataclass
class Gram:
    """The whitened cross-products of one data set.

    Attributes
    ----------
    cc, ce, cy : ndarray
        Calibration columns (12) against themselves, the effect columns and the data.
    ee, ey : ndarray
        Effect columns against themselves and the data.
    yy : float
        The data's square norm.
    n_rows : int
        Whitened rows summed (three per sample, less each run's first).
    log_scale : float
        Sum over those rows of ``log sigma`` of their axis's noise model.
    """

    cc: FloatArray
    ce: FloatArray
    cy: FloatArray
    ee: FloatArray
    ey: FloatArray
    yy: float
    n_rows: int
    log_scale: float = 0.0


def _rows(
    data: DiagnosisData, part: IntArray, forms: Sequence[Form], width: int
) -> tuple[FloatArray, FloatArray]:
    """Calibration rows (m, 4) and effect rows (m, 3, width) of the samples ``part``."""
    b = data.b_ref_body_nt[part] / FIELD_SCALE_NT
    cal = np.column_stack([b, np.ones(part.size)])
    eff = np.zeros((part.size, 3, width))
    for f in forms:
        eff[:, :, f.cols] = f.block.rows(part)
    return cal, eff


def design_rows(data: DiagnosisData, index: IntArray, forms: Sequence[Form]) -> FloatArray:
    """The columns of the calibration and of ``forms`` (numbered side by side from 0) at the
    samples ``index``, (m, 3, 12 + width): axis ``i``'s calibration columns at ``4 i .. 4 i + 3``
    as in the Gram matrix, the forms' after the 12."""
    width = max((f.cols.stop for f in forms), default=0)
    out = np.zeros((index.size, 3, 12 + width))
    for a in range(0, index.size, CHUNK_SAMPLES):
        part = index[a : a + CHUNK_SAMPLES]
        cal, eff = _rows(data, part, forms, width)
        for i in range(3):
            out[a : a + part.size, i, 4 * i : 4 * i + 4] = cal
        out[a : a + part.size, :, 12:] = eff
    return out


def _chunks(m: int, lag: int) -> list[tuple[int, int, int]]:
    """``(lo, a, b)``: rows ``lo .. b`` are built, rows ``a .. b`` kept (``lo = a - lag``)."""
    return [(max(0, a - lag), a, min(a + CHUNK_SAMPLES, m)) for a in range(0, m, CHUNK_SAMPLES)]


def whitened_gram(
    data: DiagnosisData,
    index: IntArray,
    run_start: IntArray,
    forms: Sequence[Form],
    noise: Sequence[AxisNoise],
    skip: int = 0,
) -> Gram:
    """The Gram matrix of the whitened calibration columns, effect columns and measurement over
    the samples ``index`` (runs ``run_start``, positions in ``index``). Each run's first
    ``max(skip, lag)`` samples are left out (``skip`` the same for every noise model: their
    likelihoods are then of the same rows)."""
    return whitened_grams(data, index, run_start, forms, [noise], skip)[0]


FilterGroups = list[list[tuple[FloatArray, list[int]]]]


def _filter_groups(noises: Sequence[Sequence[AxisNoise]]) -> FilterGroups:
    """Per axis, the distinct whitening filters among the noise models and which models use each
    (models sharing a filter share one pass; their Gram matrices differ by ``1 / sigma^2``)."""
    out: FilterGroups = []
    for i in range(3):
        groups: list[tuple[FloatArray, list[int]]] = []
        for k, noise in enumerate(noises):
            a = noise[i].filter
            same = [g for g in groups if np.array_equal(g[0], a)]
            if same:
                same[0][1].append(k)
            else:
                groups.append((a, [k]))
        out.append(groups)
    return out


def whitened_grams(
    data: DiagnosisData,
    index: IntArray,
    run_start: IntArray,
    forms: Sequence[Form],
    noises: Sequence[Sequence[AxisNoise]],
    skip: int = 0,
    forms_apart: bool = False,
) -> list[Gram]:
    """:func:`whitened_gram` under each of several noise models, the rows built once and each
    axis's rows filtered once per distinct filter (the innovations' ``1 / sigma^2`` applied to
    the sums). With ``forms_apart`` the products between two forms are left zero (each form
    alone against the calibration and the data: what choosing among an effect's forms reads,
    at a fraction of the products)."""
    width = max((f.cols.stop for f in forms), default=0)
    groups = _filter_groups(noises)
    sums = [[np.zeros((4 + width + 1, 4 + width + 1)) for _ in g] for g in groups]
    counts = [[0] * len(g) for g in groups]
    lag = max(skip, *(n.lag for noise in noises for n in noise))
    for lo, a, b in _chunks(index.size, lag):
        part = index[lo:b]
        cal, eff = _rows(data, part, forms, width)
        y = data.b_raw_nt[part]
        # run starts before the chunk are negative: the kept rows' history is inside it
        starts = run_start[lo:b] - lo
        kept = np.zeros(part.size, dtype=bool)
        kept[a - lo : b - lo] = True
        kept &= (np.arange(part.size) - starts) >= skip
        for i in range(3):
            z = np.concatenate([cal, eff[:, i, :], y[:, i : i + 1]], axis=1)
            for g, (filt, _) in enumerate(groups[i]):
                if filt.size == 1:  # white (a_0 = 1): no filtering
                    w = z[kept]
                else:
                    w, valid = whiten_with(filt, 1.0, z, starts)
                    w = w[valid & kept]
                counts[i][g] += w.shape[0]
                if forms_apart:
                    _add_apart(sums[i][g], w, forms)
                else:  # the upper triangle of w'w (a rank-k update: half of w.T @ w)
                    sums[i][g] += dsyrk(1.0, w.T)
    return [_assembled(groups, sums, counts, noise, k, width) for k, noise in enumerate(noises)]


def _add_apart(out: FloatArray, w: FloatArray, forms: Sequence[Form]) -> None:
    """The upper triangle of ``w'w`` (columns: 4 calibration, the forms', the data) without the
    products between two forms."""
    out[:4, :] += w[:, :4].T @ w
    out[4:, -1] += w[:, 4:].T @ w[:, -1]
    for f in forms:
        c = slice(4 + f.cols.start, 4 + f.cols.stop)
        out[c, c] += w[:, c].T @ w[:, c]


def _assembled(
    groups: FilterGroups,
    sums: list[list[FloatArray]],
    counts: list[list[int]],
    noise: Sequence[AxisNoise],
    k: int,
    width: int,
) -> Gram:
    """Noise model ``k``'s Gram matrix from the per-axis sums of its filters."""
    full = np.zeros((12 + width + 1, 12 + width + 1))
    n_rows, log_scale = 0, 0.0
    for i in range(3):
        g = next(j for j, (_, ks) in enumerate(groups[i]) if k in ks)
        ix = np.r_[4 * i : 4 * i + 4, 12 : 12 + width + 1]
        full[np.ix_(ix, ix)] += sums[i][g] / noise[i].sigma_nt ** 2
        n_rows += counts[i][g]
        log_scale += counts[i][g] * float(np.log(noise[i].sigma_nt))
    full = np.triu(full) + np.triu(full, 1).T
    c, e = slice(0, 12), slice(12, 12 + width)
    return Gram(
        cc=full[c, c],
        ce=full[c, e],
        cy=full[c, -1],
        ee=full[e, e],
        ey=full[e, -1],
        yy=float(full[-1, -1]),
        n_rows=n_rows,
        log_scale=log_scale,
    )


def apply_model(
    data: DiagnosisData,
    index: IntArray,
    forms: Sequence[Form],
    beta: FloatArray,
    theta: FloatArray,
) -> FloatArray:
    """``b_raw - (calibration + effects)`` at the samples ``index`` [nT], (m, 3): ``beta`` the 12
    calibration parameters (axis ``i``: its row of the matrix / FIELD_SCALE_NT, then its offset),
    ``theta`` the effect parameters (zero for the forms not in the model)."""
    used = [f for f in forms if np.any(theta[f.cols] != 0.0)]
    width = max((f.cols.stop for f in forms), default=0)
    out = np.empty((index.size, 3))
    for a in range(0, index.size, CHUNK_SAMPLES):
        part = index[a : a + CHUNK_SAMPLES]
        cal, eff = _rows(data, part, used, width)  # the forms of the model only
        for i in range(3):
            pred = cal @ beta[4 * i : 4 * i + 4] + eff[:, i, :] @ theta[:width]
            out[a : a + part.size, i] = data.b_raw_nt[part, i] - pred
    return out
