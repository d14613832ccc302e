"""The 12 calibration columns of every joint fit, and their orthonormal basis, from the data.

Each joint fit (:mod:`orbitcal.diagnose.attribution.joint_fit`) has the calibration's 12
parameters: per sensor axis ``i`` the row ``a[i, :]`` of the 3x3 matrix acting on the reference
field (columns ``3 i .. 3 i + 2``, the field divided by
:data:`~orbitcal.diagnose.data.FIELD_SCALE_NT`) and the offset ``o[i]`` (column ``9 + i``). The
column scales of the effects (:mod:`orbitcal.diagnose.blocked`), the attitude scan
(:mod:`orbitcal.diagnose.attitude_scan`) and the fraction of an effect the calibration absorbs
(:mod:`orbitcal.diagnose.attribution.uncertainty`) use these columns and the triangular factor of
their QR decomposition; :class:`~orbitcal.diagnose.data.DiagnosisData` stays plain data.
"""

from __future__ import annotations

import weakref

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.columns import Index, chunk_slices, triangular_factor
from orbitcal.diagnose.data import FIELD_SCALE_NT, DiagnosisData

__all__ = ["calibration_r_inv", "calibration_r_inv_of", "calibration_rows"]

#: ``R^-1`` of every ``step``-th sample, per data set and step (weakly: a data set dropped drops
#: its factors).
_R_INV: weakref.WeakKeyDictionary[DiagnosisData, dict[int, FloatArray]] = (
    weakref.WeakKeyDictionary()
)


def calibration_rows(data: DiagnosisData, index: Index) -> FloatArray:
    """The 12 calibration columns (``b_ref / FIELD_SCALE_NT`` per axis and an offset) of the
    samples ``index``, rows sample-major, shape (3 m, 12)."""
    b = data.b_ref_body_nt[index] / FIELD_SCALE_NT
    x = np.zeros((b.shape[0], 3, 12))
    for i in range(3):
        x[:, i, 3 * i : 3 * i + 3] = b
        x[:, i, 9 + i] = 1.0
    return x.reshape(-1, 12)


def calibration_r_inv_of(data: DiagnosisData, index: npt.NDArray[np.intp]) -> FloatArray:
    """Inverse ``R^-1`` (12, 12) of the triangular factor of the 12 calibration columns on the
    samples ``index``, ``X = Q R``: an orthonormal basis of the calibration there is ``X R^-1``,
    built a block of samples at a time (the whole 3N x 12 ``Q``, 288 B per sample, is never
    held)."""
    blocks = (calibration_rows(data, index[part]) for part in chunk_slices(index.size))
    return np.asarray(np.linalg.inv(triangular_factor(blocks, 12)), dtype=np.float64)


def calibration_r_inv(data: DiagnosisData, step: int = 1) -> FloatArray:
    """:func:`calibration_r_inv_of` every ``step``-th sample (all by default), computed once per
    data set and step."""
    by_step = _R_INV.setdefault(data, {})
    hit = by_step.get(step)
    if hit is None:
        hit = by_step[step] = calibration_r_inv_of(data, np.arange(0, data.n, step))
    return hit
