"""The 12-parameter vector least-squares calibration (closed form), with optional regressors.

Sensor model (Wang et al. 2020, eq. 1, with housekeeping-driven fields added):

    b_raw = A @ b_ref + b0 + K @ x_hk + ε,   ε ~ N(0, σ²I)

The noise is on the raw reading and the reference field (IGRF along the orbit, rotated by the
attitude) is exact, so regressing ``b_raw`` on ``[b_ref, 1, x_hk]`` per axis is ordinary least
squares — the maximum-likelihood estimator, efficient with covariance ``σ² (XᵀX)⁻¹`` (the
Cramér–Rao bound, :func:`cramer_rao_bound`). The calibration inverts it:
``b_cal = A⁻¹ (b_raw − b0 − K x_hk)``, i.e. ``M = A⁻¹``, ``o = b0``.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.base import AffineCalibration, FitData
from orbitcal.calibrate.errors import (
    MissingAttitudeError,
    PoorCoverageError,
    TooFewSamplesError,
    UndeterminedFitError,
)

__all__ = [
    "CONDITION_LIMIT",
    "MAX_GAIN_SD",
    "cramer_rao_bound",
    "design_matrix",
    "equilibrated_condition_number",
    "fit_linear",
    "fit_linear_batch",
]


# Largest accepted condition number of the column-equilibrated design matrix. Beyond it one
# direction of the parameter space is determined by < 1e-6 of the data's leverage.
CONDITION_LIMIT = 1e6
#: Largest standard error of an element of ``A`` (and so of ``M``) a fit may leave [-]: 0.02 is
#: ±1,000 nT of field error at 50,000 nT. A design can be well-conditioned numerically yet leave
#: ``A`` undetermined when the field barely turns in the sensor frame: 49 s of real GRACE-FO data
#: (condition 1.9e5) give standard errors up to 5; 5 min of nadir pointing at 20 nT noise 0.5;
#: 1,000 s of nadir 0.005; a day at 10 s ~1e-4 (issue 22).
MAX_GAIN_SD = 0.02


def design_matrix(b_ref_body_nt: FloatArray, x_hk: FloatArray | None = None) -> FloatArray:
    """``X = [b_ref, 1, x_hk]``, shape ``(N, 4 + k)``."""
    b = np.asarray(b_ref_body_nt, dtype=np.float64).reshape(-1, 3)
    cols = [b, np.ones((b.shape[0], 1))]
    if x_hk is not None and np.size(x_hk):
        cols.append(np.asarray(x_hk, dtype=np.float64).reshape(b.shape[0], -1))
    return np.hstack(cols)


def equilibrated_condition_number(X: FloatArray) -> float:
    """2-norm condition number of ``X`` after scaling each column to unit norm."""
    norms = np.linalg.norm(X, axis=0)
    if np.any(norms == 0.0):
        return float("inf")
    s = np.linalg.svd(X / norms, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def _check(data: FitData, method: str) -> FloatArray:
    if data.b_ref_body_nt is None:
        raise MissingAttitudeError(method)
    k = 0 if data.x_hk is None else data.x_hk.shape[1]
    n_required = 2 * (4 + k)
    if data.n < n_required:
        raise TooFewSamplesError(method, data.n, n_required)
    X = design_matrix(data.b_ref_body_nt, data.x_hk)
    cond = equilibrated_condition_number(X)
    if not cond < CONDITION_LIMIT:
        raise PoorCoverageError(method, cond, CONDITION_LIMIT)
    return X


def fit_linear(data: FitData, *, use_hk: bool = False) -> AffineCalibration:
    """Closed-form 12-parameter fit (``use_hk=False``) or "linear + regressors" (``use_hk=True``).

    Parameters
    ----------
    data
        Raw readings and the reference field in the body frame (attitude needed).
    use_hk
        Also fit ``K`` for the housekeeping regressors in ``data.x_hk``.

    Returns
    -------
    AffineCalibration
        Method ``"linear"`` or ``"linear-hk"``; ``extra`` holds ``A``, ``b0``, the residual rms
        ``sigma_nt`` and the design's ``condition_number``.

    Raises
    ------
    MissingAttitudeError, TooFewSamplesError, PoorCoverageError
    """
    method = "linear-hk" if use_hk else "linear"
    fit_data = (
        data.without_constant_hk()
        if use_hk
        else FitData(data.b_raw_nt, data.b_ref_body_nt, data.b_ref_mag_nt)
    )
    X = _check(fit_data, method)
    coef, *_ = np.linalg.lstsq(X, fit_data.b_raw_nt, rcond=None)
    A: FloatArray = np.asarray(coef[:3].T, dtype=np.float64)
    b0: FloatArray = np.asarray(coef[3], dtype=np.float64)
    K: FloatArray = np.asarray(coef[4:].T, dtype=np.float64)
    resid = fit_data.b_raw_nt - X @ coef
    dof = max(1, X.shape[0] - X.shape[1])
    sigma = float(np.sqrt(np.sum(resid**2) / (3 * dof)))
    gain_sd = _gain_standard_error(X, sigma)
    if not gain_sd <= MAX_GAIN_SD:
        raise UndeterminedFitError(method, gain_sd, MAX_GAIN_SD, int(X.shape[0]))
    return AffineCalibration(
        method,
        np.asarray(np.linalg.inv(A), dtype=np.float64),
        b0,
        K=K,
        hk_names=list(fit_data.hk_names),
        extra={
            "A": A.tolist(),
            "b0": b0.tolist(),
            "sigma_nt": sigma,
            "condition_number": equilibrated_condition_number(X),
        },
    )


def _gain_standard_error(X: FloatArray, sigma_nt: float) -> float:
    """Largest standard error of the ``A`` columns' coefficients of ``X`` [-]: ``sigma ·
    sqrt(diag((XᵀX)⁻¹))`` over the three field columns (the same for every output axis)."""
    _, r = np.linalg.qr(X)
    try:
        r_inv = np.linalg.inv(r)
    except np.linalg.LinAlgError:
        return float("inf")
    var_unit = np.sum(r_inv[:3, :] ** 2, axis=1)
    return float(sigma_nt * np.sqrt(np.max(var_unit)))


def fit_linear_batch(X: FloatArray, b_raw_nt: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Vectorised forward fits over a batch of noise realisations sharing one design.

    Parameters
    ----------
    X
        Design ``(N, p)`` from :func:`design_matrix`.
    b_raw_nt
        ``(R, N, 3)`` raw readings of ``R`` Monte-Carlo runs [nT].

    Returns
    -------
    A, b0
        ``(R, 3, 3)`` and ``(R, 3)``.
    """
    pinv = np.linalg.pinv(X)  # (p, N)
    coef: FloatArray = np.einsum("pn,rnk->rpk", pinv, b_raw_nt)
    return np.transpose(coef[:, :3, :], (0, 2, 1)), coef[:, 3, :]


def cramer_rao_bound(X: FloatArray, sigma_nt: float) -> FloatArray:
    """Cramér–Rao bound of each axis' parameters ``[A_k1, A_k2, A_k3, b0_k, K_k…]``.

    For the linear Gaussian model ``y = X θ + ε`` the Fisher information is ``XᵀX/σ²``, so
    ``Cov(θ̂) ⪰ σ² (XᵀX)⁻¹`` (Kay 1993, "Fundamentals of Statistical Signal Processing I", eq. 3.30),
    identical for the three axes.

    Returns
    -------
    ndarray, shape (p, p)
        [nT² / unit²].
    """
    out: FloatArray = np.asarray(sigma_nt**2 * np.linalg.inv(X.T @ X), dtype=np.float64)
    return out
