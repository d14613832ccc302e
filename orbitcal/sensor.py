"""The magnetometer error model of Wang et al. (2020), eq. 1.

    B_m = A · B + B_0 + ΔB

with ``B`` the true field in the body (sensor) axes [nT], ``A`` the 3×3 matrix of scale factors,
non-orthogonality and soft iron, ``B_0`` the constant bias ("constant drift", hard iron) [nT] and
``ΔB`` white Gaussian noise of standard deviation ``σ`` [nT] on each axis.

Wang, Y.K., Sheng, T., He, L. and Cheng, Z.Y. (2020) Calibration Method of Magnetometer Based on BP
Neural Network. Journal of Computer and Communications, 8, 31-41. doi:10.4236/jcc.2020.86004.
Their ground parameters are eq. 15, the in-orbit change (from t = 15 s) eq. 17, noise σ = 2 nT.

The exact inverse is linear: ``B = M (B_m − o)`` with ``M = A⁻¹`` and ``o = B_0`` — the ``linear``
block of the calibration document (CONTRACT section 4).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError

__all__ = [
    "WANG2020_GROUND_A",
    "WANG2020_GROUND_B0_NT",
    "WANG2020_NOISE_STD_NT",
    "WANG2020_ORBIT_A",
    "WANG2020_ORBIT_B0_NT",
    "SensorModel",
]


#: Wang et al. (2020) eq. 15: coefficient matrix of the ground error model.
WANG2020_GROUND_A: tuple[tuple[float, float, float], ...] = (
    (0.9599, -0.0209, -0.0065),
    (0.0020, 0.9476, -0.0040),
    (0.0011, 0.0561, 0.9657),
)
#: Wang et al. (2020) eq. 15: constant drift (bias) [nT].
WANG2020_GROUND_B0_NT: tuple[float, float, float] = (-633.2, 1281.7, -455.5)
#: Wang et al. (2020) eq. 17: coefficient matrix after the change in orbit (t > 15 s).
WANG2020_ORBIT_A: tuple[tuple[float, float, float], ...] = (
    (0.9579, -0.0209, -0.0065),
    (0.0020, 0.9456, -0.0040),
    (0.0011, 0.0561, 0.9637),
)
#: Wang et al. (2020) eq. 17: constant drift after the change [nT].
WANG2020_ORBIT_B0_NT: tuple[float, float, float] = (-652.7, 1266.4, -444.49)
#: Wang et al. (2020) section 4: "random noise with the mean value of 0 and the standard deviation
#: of 2" [nT].
WANG2020_NOISE_STD_NT = 2.0


@dataclass(frozen=True, eq=False)
class SensorModel:
    """Wang 2020 eq. 1 sensor: ``b_raw = A @ b_true + b0 + N(0, σ²)`` per sample.

    Attributes
    ----------
    a_matrix : ndarray, shape (3, 3)
        Scale, non-orthogonality and soft-iron matrix ``A`` (dimensionless), sensor ← body axes.
    bias_nt : ndarray, shape (3,)
        Constant bias ``B_0`` in sensor axes [nT].
    noise_std_nt : float
        Standard deviation of the white noise ``ΔB`` on each axis [nT].
    """

    a_matrix: FloatArray = field(default_factory=lambda: np.eye(3))
    bias_nt: FloatArray = field(default_factory=lambda: np.zeros(3))
    noise_std_nt: float = 0.0

    def __post_init__(self) -> None:
        a = np.asarray(self.a_matrix, dtype=np.float64)
        b0 = np.asarray(self.bias_nt, dtype=np.float64)
        if a.shape != (3, 3):
            raise BadInputError(f"a_matrix must be 3×3, got shape {a.shape}")
        if b0.shape != (3,):
            raise BadInputError(f"bias_nt must have shape (3,), got {b0.shape}")
        if not np.isfinite(self.noise_std_nt) or self.noise_std_nt < 0:
            raise BadInputError(f"noise_std_nt must be finite and ≥ 0, got {self.noise_std_nt}")
        if abs(np.linalg.det(a)) < 1e-6:
            raise BadInputError("a_matrix is singular: a magnetometer must see every axis")
        object.__setattr__(self, "a_matrix", a)
        object.__setattr__(self, "bias_nt", b0)
        object.__setattr__(self, "noise_std_nt", float(self.noise_std_nt))

    # --- the model ---------------------------------------------------------------------------

    def measure_noiseless(self, b_true_body_nt: npt.ArrayLike) -> FloatArray:
        """``A @ b + B_0`` without noise [nT], shape (N, 3) (or (3,))."""
        b = np.asarray(b_true_body_nt, dtype=np.float64)
        return b @ self.a_matrix.T + self.bias_nt

    def measure(self, b_true_body_nt: npt.ArrayLike, *, rng: np.random.Generator) -> FloatArray:
        """Simulate the raw output, Wang 2020 eq. 1.

        Parameters
        ----------
        b_true_body_nt : array_like, shape (N, 3)
            True field in body axes [nT].
        rng : numpy.random.Generator
            Source of the noise ``ΔB`` (seeded by the caller).

        Returns
        -------
        ndarray, shape (N, 3)
            Raw magnetometer output in sensor axes [nT].
        """
        clean = self.measure_noiseless(b_true_body_nt)
        if self.noise_std_nt == 0.0:
            return clean
        return clean + rng.normal(0.0, self.noise_std_nt, size=clean.shape)

    def invert(self, b_raw_nt: npt.ArrayLike) -> FloatArray:
        """The exact linear calibration ``A⁻¹ (b_raw − B_0)`` [nT], body axes."""
        b = np.asarray(b_raw_nt, dtype=np.float64)
        return (b - self.bias_nt) @ np.linalg.inv(self.a_matrix).T

    @property
    def linear(self) -> dict[str, list[Any]]:
        """The calibration that undoes this sensor, CONTRACT section 4 ``{"M": A⁻¹, "o": B_0}``."""
        return {"M": np.linalg.inv(self.a_matrix).tolist(), "o": self.bias_nt.tolist()}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (``A``, ``b0_nt``, ``noise_std_nt``)."""
        return {
            "A": self.a_matrix.tolist(),
            "b0_nt": self.bias_nt.tolist(),
            "noise_std_nt": self.noise_std_nt,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SensorModel:
        """Inverse of :meth:`to_dict`."""
        return cls(
            a_matrix=np.asarray(d["A"], dtype=np.float64),
            bias_nt=np.asarray(d["b0_nt"], dtype=np.float64),
            noise_std_nt=float(d["noise_std_nt"]),
        )

    # --- published and random parameter sets ------------------------------------------------

    @classmethod
    def from_wang2020_ground(cls, *, noise_std_nt: float = WANG2020_NOISE_STD_NT) -> SensorModel:
        """The ground error model of Wang et al. (2020) eq. 15 (σ = 2 nT)."""
        return cls(
            a_matrix=np.array(WANG2020_GROUND_A),
            bias_nt=np.array(WANG2020_GROUND_B0_NT),
            noise_std_nt=noise_std_nt,
        )

    @classmethod
    def wang2020_orbit_change(cls, *, noise_std_nt: float = WANG2020_NOISE_STD_NT) -> SensorModel:
        """The changed in-orbit model of Wang et al. (2020) eq. 17 (valid for t > 15 s)."""
        return cls(
            a_matrix=np.array(WANG2020_ORBIT_A),
            bias_nt=np.array(WANG2020_ORBIT_B0_NT),
            noise_std_nt=noise_std_nt,
        )

    def with_wang2020_change(self) -> SensorModel:
        """This sensor after the in-orbit change of Wang 2020: ``A + (A₁₇ − A₁₅)``,
        ``B_0 + (B₀,₁₇ − B₀,₁₅)`` (diagonal −0.002, bias (−19.5, −15.3, +11.01) nT)."""
        return SensorModel(
            a_matrix=self.a_matrix + np.array(WANG2020_ORBIT_A) - np.array(WANG2020_GROUND_A),
            bias_nt=self.bias_nt + np.array(WANG2020_ORBIT_B0_NT) - np.array(WANG2020_GROUND_B0_NT),
            noise_std_nt=self.noise_std_nt,
        )

    @classmethod
    def random(
        cls,
        *,
        rng: np.random.Generator,
        scale_std: float = 0.03,
        misalignment_std_deg: float = 0.5,
        bias_std_nt: float = 500.0,
        noise_std_nt: float = 2.0,
    ) -> SensorModel:
        """A plausible uncalibrated fluxgate (the spread of Wang 2020 eq. 15 by default).

        Parameters
        ----------
        rng : numpy.random.Generator
            Seeded source.
        scale_std : float
            Standard deviation of the scale factors about 1 (dimensionless).
        misalignment_std_deg : float
            Standard deviation of the off-diagonal (non-orthogonality, misalignment) terms [deg].
        bias_std_nt : float
            Standard deviation of each bias component [nT].
        noise_std_nt : float
            White noise per axis [nT].
        """
        a = np.diag(1.0 + rng.normal(0.0, scale_std, 3))
        off = rng.normal(0.0, np.deg2rad(misalignment_std_deg), (3, 3))
        np.fill_diagonal(off, 0.0)
        return cls(
            a_matrix=a + off,
            bias_nt=rng.normal(0.0, bias_std_nt, 3),
            noise_std_nt=noise_std_nt,
        )
