"""The accuracy vocabulary: one name and one definition per root mean square (CONTRACT §4–5).

Every surface (the calibration document, ``orbitcal calibrate``, the diagnosis report, the HTTP
routes and the dashboard) computes its figures with these functions, so the same data give the
same number everywhere.

- ``rms_nt``: a key ending in ``_rms_nt`` whose name says nothing else is
  ``sqrt(mean((b_cal − b_ref)²))`` over the ``N × 3`` array — samples **and** components.
- ``norm_rms_nt``: the RMS of the vector magnitude ``‖b_cal − b_ref‖``, i.e. ``√3 ×`` ``rms_nt``
  for the same residual.
- ``scalar_rms_nt``: the RMS of ``‖b_cal‖ − |B_ref|`` (what an attitude-free method can see).

For scalar-only methods, the document's ``holdout_rms_nt`` is the scalar one, as its ``method``
tells (:func:`primary_key`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray

__all__ = ["KEYS", "norm_rms_nt", "primary_key", "rms_nt", "rms_nt_from_norm", "scalar_rms_nt"]


#: The three names, in the order documents and answers list them.
KEYS: tuple[str, ...] = ("rms_nt", "norm_rms_nt", "scalar_rms_nt")


def _residual(b_cal_nt: npt.ArrayLike, b_ref_nt: npt.ArrayLike | None) -> FloatArray:
    b = np.asarray(b_cal_nt, dtype=np.float64)
    return b if b_ref_nt is None else b - np.asarray(b_ref_nt, dtype=np.float64)


def rms_nt(b_cal_nt: npt.ArrayLike, b_ref_nt: npt.ArrayLike | None = None) -> float:
    """``sqrt(mean((b_cal − b_ref)²))`` over samples and the three components [nT].

    Parameters
    ----------
    b_cal_nt : array_like, shape (N, 3)
        Calibrated field [nT, body frame], or the residual itself when ``b_ref_nt`` is None.
    b_ref_nt : array_like, shape (N, 3), optional
        Reference field [nT, body frame].

    Returns
    -------
    float
        NaN for no samples.
    """
    r = _residual(b_cal_nt, b_ref_nt)
    return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")


def norm_rms_nt(b_cal_nt: npt.ArrayLike, b_ref_nt: npt.ArrayLike | None = None) -> float:
    """``sqrt(mean(‖b_cal − b_ref‖²))`` over samples [nT] (``√3 × rms_nt`` of the same residual).

    Parameters as :func:`rms_nt`; the last axis holds the three components.
    """
    r = _residual(b_cal_nt, b_ref_nt)
    return float(np.sqrt(np.mean(np.sum(r**2, axis=-1)))) if r.size else float("nan")


def scalar_rms_nt(b_cal_nt: npt.ArrayLike, b_ref_mag_nt: npt.ArrayLike) -> float:
    """``sqrt(mean((‖b_cal‖ − |B_ref|)²))`` over samples [nT].

    Parameters
    ----------
    b_cal_nt : array_like, shape (N, 3)
        Calibrated field [nT].
    b_ref_mag_nt : array_like, shape (N,)
        Reference field magnitude [nT] (frame-free).
    """
    b = np.asarray(b_cal_nt, dtype=np.float64)
    if not b.size:
        return float("nan")
    d = np.linalg.norm(b, axis=-1) - np.asarray(b_ref_mag_nt, dtype=np.float64)
    return float(np.sqrt(np.mean(d**2)))


def rms_nt_from_norm(norm_rms: float) -> float:
    """``rms_nt`` of a residual whose ``norm_rms_nt`` is given: exactly ``norm_rms / √3``.

    (``mean(‖r‖²) = 3 · mean(r²)`` over the ``N × 3`` array.) For code that accumulates the norm
    form internally, such as the diagnosis's attribution, and reports in the contract's vocabulary.
    """
    return float(norm_rms) / float(np.sqrt(3.0))


def primary_key(*, vector: bool) -> str:
    """The metric a method is judged by: ``rms_nt`` for vector methods, else ``scalar_rms_nt``."""
    return "rms_nt" if vector else "scalar_rms_nt"
