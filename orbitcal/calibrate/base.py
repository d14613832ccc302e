"""The common interface of every calibrator, the fit inputs, and the affine calibration.

Conventions (CONTRACT section 4): a calibration maps raw sensor-axis readings ``b_raw_nt`` (and, for
some methods, housekeeping regressors ``x_hk``) to the calibrated field in the body frame
``b_cal_nt``; its best linear approximation is ``b_cal = M @ (b_raw - o)``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.errors import DocumentError
from orbitcal.errors import BadInputError

__all__ = [
    "AffineCalibration",
    "Calibration",
    "FitData",
    "as_hk",
    "best_linear_approximation",
]


def as_hk(x_hk: FloatArray | None, n: int) -> FloatArray:
    """Housekeeping regressors as a float64 ``(n, k)`` array (``k = 0`` when ``None``)."""
    if x_hk is None:
        return np.zeros((n, 0))
    x = np.asarray(x_hk, dtype=np.float64)
    return x.reshape(n, -1)


@dataclass
class FitData:
    """What a calibrator is fitted on.

    Attributes
    ----------
    b_raw_nt
        Raw magnetometer output, sensor axes, ``(N, 3)`` [nT].
    b_ref_body_nt
        Reference field in the body frame, ``(N, 3)`` [nT], or ``None`` without attitude
        (then only attitude-free scalar methods apply).
    b_ref_mag_nt
        Reference field magnitude ``(N,)`` [nT]; defaults to ``‖b_ref_body_nt‖``.
    x_hk
        Housekeeping regressors ``(N, k)`` (temperature [°C], ``mtq_*`` [A·m²], ``hk_*``).
    hk_names
        Their column names, length ``k``.
    """

    b_raw_nt: FloatArray
    b_ref_body_nt: FloatArray | None = None
    b_ref_mag_nt: FloatArray | None = None
    x_hk: FloatArray | None = None
    hk_names: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.b_raw_nt = np.asarray(self.b_raw_nt, dtype=np.float64).reshape(-1, 3)
        n = self.b_raw_nt.shape[0]
        if self.b_ref_body_nt is not None:
            self.b_ref_body_nt = np.asarray(self.b_ref_body_nt, dtype=np.float64).reshape(n, 3)
            if self.b_ref_mag_nt is None:
                self.b_ref_mag_nt = np.linalg.norm(self.b_ref_body_nt, axis=1)
        if self.b_ref_mag_nt is not None:
            self.b_ref_mag_nt = np.asarray(self.b_ref_mag_nt, dtype=np.float64).reshape(n)
        self.x_hk = as_hk(self.x_hk, n)
        if self.x_hk.shape[1] != len(self.hk_names):
            raise ValueError(
                f"x_hk has {self.x_hk.shape[1]} columns "
                f"but {len(self.hk_names)} hk_names were given"
            )

    @property
    def n(self) -> int:
        return int(self.b_raw_nt.shape[0])

    def without_constant_hk(self) -> FitData:
        """The same data without housekeeping columns that do not vary (they carry no
        information and would make the design singular)."""
        assert self.x_hk is not None
        if self.x_hk.shape[1] == 0:
            return self
        keep = np.ptp(self.x_hk, axis=0) > 0 if self.n else np.zeros(self.x_hk.shape[1], bool)
        if bool(np.all(keep)):
            return self
        return FitData(
            self.b_raw_nt,
            self.b_ref_body_nt,
            self.b_ref_mag_nt,
            self.x_hk[:, keep],
            [n for n, k in zip(self.hk_names, keep, strict=True) if k],
        )

    def subset(self, mask: NDArray[np.bool_] | NDArray[np.int64]) -> FitData:
        """The same data restricted to ``mask`` (boolean or index array)."""
        return FitData(
            self.b_raw_nt[mask],
            None if self.b_ref_body_nt is None else self.b_ref_body_nt[mask],
            None if self.b_ref_mag_nt is None else self.b_ref_mag_nt[mask],
            None if self.x_hk is None else self.x_hk[mask],
            list(self.hk_names),
        )


class Calibration(ABC):
    """A fitted calibration: raw readings (+ housekeeping) → calibrated body-frame field [nT]."""

    method: str
    hk_names: list[str]

    @abstractmethod
    def apply(self, b_raw_nt: FloatArray, x_hk: FloatArray | None = None) -> FloatArray:
        """Calibrated field ``(N, 3)`` [nT, body frame] from raw ``(N, 3)`` [nT, sensor axes]."""

    @abstractmethod
    def linear(self) -> tuple[FloatArray, FloatArray]:
        """``(M, o)`` with ``b_cal ≈ M @ (b_raw − o)``: exact for linear methods (``x_hk = 0``)."""

    @abstractmethod
    def to_model(self) -> dict[str, Any]:
        """The method-specific ``model`` block of the CONTRACT section-4 document (JSON-ready)."""

    @classmethod
    @abstractmethod
    def from_model(cls, method: str, model: dict[str, Any]) -> Calibration:
        """Rebuild from :meth:`to_model` output (bit-for-bit)."""


def best_linear_approximation(
    cal: Calibration, b_raw_nt: FloatArray, x_hk: FloatArray | None = None
) -> tuple[FloatArray, FloatArray]:
    """Least-squares ``(M, o)`` with ``cal.apply(b_raw) ≈ M @ (b_raw − o)`` over these samples."""
    b_raw = np.asarray(b_raw_nt, dtype=np.float64)
    b_cal = cal.apply(b_raw, x_hk)
    X = np.column_stack([b_raw, np.ones(len(b_raw))])
    coef, *_ = np.linalg.lstsq(X, b_cal, rcond=None)
    M: FloatArray = np.asarray(coef[:3].T, dtype=np.float64)
    o: FloatArray = -np.linalg.solve(M, coef[3])
    return M, o


class AffineCalibration(Calibration):
    """``b_cal = M @ (b_raw − o − K @ x_hk)``: the linear methods' common form.

    Parameters
    ----------
    method
        Registered method name.
    M
        ``(3, 3)`` [–].
    o
        ``(3,)`` [nT], offset in sensor axes.
    K
        ``(3, k)`` [nT per regressor unit]: housekeeping-driven fields in sensor axes (``k = 0``).
    hk_names
        Regressor names, length ``k``.
    extra
        Method-specific values kept in the model block (e.g. condition number, ``A``).
    """

    def __init__(
        self,
        method: str,
        M: FloatArray,
        o: FloatArray,
        *,
        K: FloatArray | None = None,
        hk_names: list[str] | None = None,
        extra: dict[str, Any] | None = None,
    ) -> None:
        self.method = method
        self.M = np.asarray(M, dtype=np.float64).reshape(3, 3)
        self.o = np.asarray(o, dtype=np.float64).reshape(3)
        self.hk_names = list(hk_names or [])
        k = len(self.hk_names)
        self.K = np.zeros((3, k)) if K is None else np.asarray(K, dtype=np.float64).reshape(3, k)
        self.extra = dict(extra or {})

    def apply(self, b_raw_nt: FloatArray, x_hk: FloatArray | None = None) -> FloatArray:
        b = np.asarray(b_raw_nt, dtype=np.float64).reshape(-1, 3) - self.o
        if self.K.shape[1]:
            x = as_hk(x_hk, b.shape[0])
            if x.shape[1] != self.K.shape[1]:
                raise BadInputError(
                    f"{self.method} needs housekeeping columns {self.hk_names}, "
                    f"got {x.shape[1]} columns"
                )
            b = b - x @ self.K.T
        out: FloatArray = b @ self.M.T
        return out

    def linear(self) -> tuple[FloatArray, FloatArray]:
        return self.M.copy(), self.o.copy()

    def to_model(self) -> dict[str, Any]:
        return {
            "form": "b_cal = M @ (b_raw - o - K @ x_hk)",
            "M": self.M.tolist(),
            "o": self.o.tolist(),
            "K": self.K.tolist(),
            "inputs": ["b_x", "b_y", "b_z", *self.hk_names],
            "hk_names": list(self.hk_names),
            **self.extra,
        }

    @classmethod
    def from_model(cls, method: str, model: dict[str, Any]) -> AffineCalibration:
        try:
            hk = [str(h) for h in model.get("hk_names", [])]
            K = np.asarray(model.get("K", [[], [], []]), dtype=np.float64).reshape(3, len(hk))
            extra = {
                k: v
                for k, v in model.items()
                if k not in {"form", "M", "o", "K", "inputs", "hk_names"}
            }
            return cls(
                method,
                np.asarray(model["M"]),
                np.asarray(model["o"]),
                K=K,
                hk_names=hk,
                extra=extra,
            )
        except (KeyError, ValueError, TypeError) as exc:
            raise DocumentError(f"malformed {method} model block: {exc}") from exc
