"""Attitude-free (scalar) calibration: TWOSTEP and the FLANN method of seed ``001``.

Both match the magnitude of the calibrated reading to a reference magnitude per sample (the model
field along the orbit, or — on the ground — a constant); neither needs attitude, so neither can see
a rotation of the sensor axes: the calibrated vector is in the *sensor* frame, corrected for scale,
non-orthogonality and offset.

**TWOSTEP** (Alonso & Shuster 2002, "Complete linear attitude-independent magnetometer
calibration", J. Astronaut. Sci. 50(4), 477-490): model ``(I + D) B_k = O A_k H_k + b + ε_k``
with ``D`` symmetric. The scalar measurement
``z_k = |B_k|² − |H_k|² = −B_kᵀ E B_k + 2 B_kᵀ c − |b|²`` with ``E = 2D + D²``,
``c = (I + D) b`` is linear in ``(E, c, |b|²)``. Step 1 solves it by linear least squares with
``|b|²`` as a free nuisance parameter (their "centred" estimate); step 2 refines ``(D, b)`` by
Gauss–Newton (here :func:`levenberg_marquardt`) on the magnitude residual
``|(I + D) B_k − b| − |H_k|``, which carries the sensor noise at unit gain.
Calibration: ``b_cal = (I + D) B − b``, i.e. ``M = I + D``, ``o = (I + D)⁻¹ b``.

**FLANN** (Wu Dehui & Huang Songling, "FLANN-based error correction of a three-axis magnetometer",
seed ``001``, eqs. 5-10): ``B̂ = C B′ − B′_0`` with ``C`` upper triangular (``c11, c22, c33, c12,
c13, c23``; the seed fixes ``c33 = 1``, OZ being its standard axis, which we keep as an option)
and offset ``B′_0``; the functional-link net expands ``B′`` into the products that make ``‖B̂‖²``
linear in its weights and trains them until ``‖B̂‖`` matches the reference magnitude. The seed
trains by the delta rule (α = 0.001, 795 iterations); we train the same net by LM, which reaches
the same minimum in a few epochs. ``M = C``, ``o = C⁻¹ B′_0``.
"""

from __future__ import annotations

import numpy as np
import torch

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.base import AffineCalibration, FitData
from orbitcal.calibrate.errors import PoorCoverageError, TooFewSamplesError
from orbitcal.calibrate.linear import CONDITION_LIMIT, equilibrated_condition_number
from orbitcal.calibrate.lm import LMOptions, levenberg_marquardt

__all__ = [
    "fit_flann",
    "fit_twostep",
    "scalar_residual_nt",
]


_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def scalar_residual_nt(b_cal_nt: FloatArray, b_ref_mag_nt: FloatArray) -> FloatArray:
    """``‖b_cal‖ − |B_ref|`` per sample [nT]."""
    out: FloatArray = np.linalg.norm(b_cal_nt, axis=1) - np.asarray(b_ref_mag_nt)
    return out


def _reference(data: FitData, method: str, n_params: int) -> FloatArray:
    if data.n < 2 * n_params:
        raise TooFewSamplesError(method, data.n, 2 * n_params)
    if data.b_ref_mag_nt is not None:
        return data.b_ref_mag_nt
    # ground use (seed 001): the mean measured magnitude as the reference
    return np.full(data.n, float(np.mean(np.linalg.norm(data.b_raw_nt, axis=1))))


def _twostep_linear(B: FloatArray, H2: FloatArray, method: str) -> tuple[FloatArray, FloatArray]:
    """Step 1: linear LS for ``E`` (6), ``c`` (3) and the nuisance ``|b|²``; returns ``(D, b)``."""
    s = float(np.median(np.linalg.norm(B, axis=1)))
    Bs = B / s
    z = (np.sum(B**2, axis=1) - H2) / s**2
    quad = [-(Bs[:, i] * Bs[:, j]) * (1.0 if i == j else 2.0) for i, j in _SYM]  # −Bᵀ E B terms
    # With a constant reference (ground use) the nuisance column is collinear with |B|² − H²
    # and the system has the trivial solution I + E = 0; |b|² ≪ H² then, so step 1 drops it.
    varying = float(np.ptp(H2)) > 1e-6 * float(np.median(H2))
    nuisance = [-np.ones(len(Bs))] if varying else []
    X = np.column_stack([*quad, 2 * Bs, *nuisance])
    cond = equilibrated_condition_number(X)
    if not cond < CONDITION_LIMIT:
        raise PoorCoverageError(method, cond, CONDITION_LIMIT)
    theta, *_ = np.linalg.lstsq(X, z, rcond=None)
    E = np.zeros((3, 3))
    for k, (i, j) in enumerate(_SYM):
        E[i, j] = E[j, i] = theta[k]
    # I + E = (I + D)²  ⇒  I + D = sqrtm(I + E) (symmetric, positive definite near identity)
    w, V = np.linalg.eigh(np.eye(3) + E)
    if np.any(w <= 0):
        raise PoorCoverageError(method, float(w.max() / max(abs(w.min()), 1e-300)), CONDITION_LIMIT)
    I_D = (V * np.sqrt(w)) @ V.T
    c = theta[6:9] * s
    b = np.linalg.solve(I_D, c)
    return I_D - np.eye(3), b


class _MagnitudeProblem:
    """``r_k = |M(θ) B_k − o(θ)| − |H_k|`` [scaled nT] for a parametrised ``M``."""

    def __init__(self, B: FloatArray, H: FloatArray, kind: str, scale: float) -> None:
        self.B = torch.from_numpy(B / scale)
        self.H = torch.from_numpy(H / scale)
        self.kind = kind

    def matrix(self, p: torch.Tensor) -> torch.Tensor:
        if self.kind == "sym":  # I + D, D symmetric
            d = p[:6]
            row0 = torch.stack([1 + d[0], d[3], d[4]])
            row1 = torch.stack([d[3], 1 + d[1], d[5]])
            row2 = torch.stack([d[4], d[5], 1 + d[2]])
        else:  # upper triangular C
            z = torch.zeros((), dtype=p.dtype)
            row0 = torch.stack([p[0], p[3], p[4]])
            row1 = torch.stack([z, p[1], p[5]])
            row2 = torch.stack([z, z, p[2]])
        return torch.stack([row0, row1, row2])

    def residuals(self, p: torch.Tensor) -> torch.Tensor:
        M = self.matrix(p)
        v = self.B @ M.T - p[6:9]
        return torch.linalg.vector_norm(v, dim=1) - self.H

    def residuals_and_jacobian(self, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Analytic: ``∂r/∂θ = (v/|v|)ᵀ ∂v/∂θ`` with ``v = M B − o``."""
        M = self.matrix(p)
        v = self.B @ M.T - p[6:9]
        norm = torch.linalg.vector_norm(v, dim=1)
        u = v / norm.unsqueeze(1)
        B = self.B
        cols = [u[:, i] * B[:, i] for i in range(3)]  # diagonal entries
        for i, j in ((0, 1), (0, 2), (1, 2)):
            if self.kind == "sym":
                cols.append(u[:, i] * B[:, j] + u[:, j] * B[:, i])
            else:
                cols.append(u[:, i] * B[:, j])
        J = torch.stack([*cols, -u[:, 0], -u[:, 1], -u[:, 2]], dim=1)
        return norm - self.H, J


class _FixedC33:
    """The upper-triangular problem with ``c33 = 1`` held fixed (seed 001)."""

    def __init__(self, full: _MagnitudeProblem) -> None:
        self.full = full

    @staticmethod
    def _expand(q: torch.Tensor) -> torch.Tensor:
        return torch.cat([q[:2], torch.ones(1, dtype=q.dtype), q[2:]])

    def residuals(self, q: torch.Tensor) -> torch.Tensor:
        return self.full.residuals(self._expand(q))

    def residuals_and_jacobian(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r, J = self.full.residuals_and_jacobian(self._expand(q))
        return r, torch.cat([J[:, :2], J[:, 3:]], dim=1)


def fit_twostep(data: FitData, *, options: LMOptions | None = None) -> AffineCalibration:
    """TWOSTEP (Alonso & Shuster 2002): linear centred estimate, then Gauss–Newton refinement.

    Parameters
    ----------
    data
        Raw readings; the reference magnitude per sample (``b_ref_mag_nt``), or none for the
        ground case (constant field: the mean measured magnitude is used).
    options
        LM options of the refinement step.

    Returns
    -------
    AffineCalibration
        ``M = I + D`` (symmetric), ``o = (I + D)⁻¹ b``; ``extra`` holds ``D``, ``b`` and the
        scalar residual rms.
    """
    method = "twostep"
    H = _reference(data, method, 9)
    B = data.b_raw_nt
    D, b = _twostep_linear(B, H**2, method)
    scale = float(np.median(H))
    problem = _MagnitudeProblem(B, H, "sym", scale)
    p0 = torch.tensor(
        [D[0, 0], D[1, 1], D[2, 2], D[0, 1], D[0, 2], D[1, 2], *(b / scale)], dtype=torch.float64
    )
    res = levenberg_marquardt(problem, p0, options=options or LMOptions(max_epochs=50))
    p = res.params
    M = problem.matrix(p).numpy()
    bb = p[6:9].numpy() * scale
    rms = float(np.sqrt(res.mse)) * scale
    return AffineCalibration(
        method,
        M,
        np.linalg.solve(M, bb),
        extra={
            "D": (M - np.eye(3)).tolist(),
            "b": bb.tolist(),
            "scalar_rms_nt": rms,
            "epochs": res.epochs,
        },
    )


def fit_flann(
    data: FitData, *, fix_c33: bool = False, options: LMOptions | None = None
) -> AffineCalibration:
    """FLANN scalar calibration (seed 001): upper-triangular ``C`` and offset, ‖B̂‖ → |B_ref|.

    Parameters
    ----------
    data
        Raw readings with the reference magnitude per sample, or none (ground: mean magnitude).
    fix_c33
        Keep ``c33 = 1`` (the seed's choice of OZ as the standard axis).
    options
        LM options.

    Returns
    -------
    AffineCalibration
        ``M = C``, ``o = C⁻¹ B′_0``.
    """
    method = "flann"
    H = _reference(data, method, 9)
    B = data.b_raw_nt
    # initial weights from the linear (TWOSTEP step 1) solution, made upper triangular:
    # (I+D)² = CᵀC  ⇒  C = chol((I+D)²)ᵀ
    D, b = _twostep_linear(B, H**2, method)
    IpD = np.eye(3) + D
    C0 = np.linalg.cholesky(IpD @ IpD).T
    b0 = C0 @ np.linalg.solve(IpD, b)  # same offset in sensor axes
    if fix_c33:
        C0, b0 = C0 / C0[2, 2], b0 / C0[2, 2]
    scale = float(np.median(H))
    problem = _MagnitudeProblem(B, H, "upper", scale)
    p0 = torch.tensor(
        [C0[0, 0], C0[1, 1], C0[2, 2], C0[0, 1], C0[0, 2], C0[1, 2], *(b0 / scale)],
        dtype=torch.float64,
    )
    if fix_c33:
        res = levenberg_marquardt(
            _FixedC33(problem),
            torch.cat([p0[:2], p0[3:]]),
            options=options or LMOptions(max_epochs=50),
        )
        p = torch.cat([res.params[:2], torch.ones(1, dtype=torch.float64), res.params[2:]])
    else:
        res = levenberg_marquardt(problem, p0, options=options or LMOptions(max_epochs=50))
        p = res.params
    C = problem.matrix(p).numpy()
    off = p[6:9].numpy() * scale
    return AffineCalibration(
        method,
        C,
        np.linalg.solve(C, off),
        extra={
            "C": C.tolist(),
            "B0": off.tolist(),
            "fix_c33": fix_c33,
            "scalar_rms_nt": float(np.sqrt(res.mse)) * scale,
            "epochs": res.epochs,
        },
    )
