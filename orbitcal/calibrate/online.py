"""Online calibration: the seed-002 one-sample ellipsoid estimator; periodic window retraining.

``OnlineEllipsoid`` follows the patent of Chen Zhongxue (CN, 2023, "Neural-network autonomous
calibration of a three-axis MEMS magnetometer", seed ``002``): ellipsoid parameters ``η`` are
updated one sample at a time from the vector ``D`` of quadratic and linear terms of the reading
``m``, the error is taken against a reference magnitude (the patent's running mean of ‖m‖, step
52; on orbit the model field magnitude of each sample), and the calibration follows from ``η`` as
``A → G = chol(A)``, offset ``X_0``, output ``G (m − X_0)`` (patent steps 9-10).

The patent's formulas for ``D`` and ``η → A`` are images missing from the seed text; we use the
standard algebraic ellipsoid ``|B_ref|² = mᵀ A m − 2 X_0ᵀ A m + c`` with
``D = [m_x², m_y², m_z², 2m_xm_y, 2m_xm_z, 2m_ym_z, m_x, m_y, m_z, 1]`` (one constant term beyond
the patent's nine, needed when the reference magnitude varies along the orbit). The patent trains a
sigmoid network one sample at a time on this error; the one-sample minimiser of the same squared
error for an output linear in ``η`` is recursive least squares, which we use (with a forgetting
factor so it tracks parameter changes).

``PeriodicRetrainer`` is the periodic on-orbit retraining of Wang et al. (2020, section 4): every
``period_s`` it refits on the samples of the last ``window_s``, warm-started from the calibration in
service.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.base import AffineCalibration, Calibration, FitData
from orbitcal.calibrate.errors import PoorCoverageError, TooFewSamplesError
from orbitcal.calibrate.linear import CONDITION_LIMIT

__all__ = [
    "OnlineEllipsoid",
    "PeriodicRetrainer",
    "RetrainEvent",
    "ellipsoid_features",
    "eta_to_calibration",
    "fit_online",
]


def ellipsoid_features(m_nt: FloatArray, *, scale_nt: float) -> FloatArray:
    """``D`` for readings ``m (N, 3)`` [nT] normalised by ``scale_nt``: shape ``(N, 10)``."""
    m = np.asarray(m_nt, dtype=np.float64).reshape(-1, 3) / scale_nt
    x, y, z = m[:, 0], m[:, 1], m[:, 2]
    return np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, x, y, z, np.ones_like(x)]
    )


def eta_to_calibration(
    eta: FloatArray, *, scale_nt: float, method: str = "online"
) -> AffineCalibration:
    """Patent step 9: ``η → A``, ``G = chol(A)`` (upper factor, ``A = GᵀG``), ``X_0``.

    ``b_cal = G (m − X_0)``; so ``linear.M = G`` and ``linear.o = X_0`` (CONTRACT section 4).

    Raises
    ------
    PoorCoverageError
        When ``A`` is not positive definite (the samples do not pin down an ellipsoid).
    """
    e = np.asarray(eta, dtype=np.float64)
    A = np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]])
    try:
        Lc = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        w = np.linalg.eigvalsh(A)
        cond = float(abs(w[-1]) / max(abs(w[0]), 1e-300))
        raise PoorCoverageError(method, cond, float("inf")) from None
    G = Lc.T  # upper triangular, A = GᵀG
    # linear terms: −2 X0ᵀ A m  ⇒  A X0 = −½ [η7, η8, η9]
    X0 = np.linalg.solve(A, -0.5 * e[6:9])
    return AffineCalibration(
        method,
        G,
        X0 * scale_nt,
        extra={"eta": e.tolist(), "eta_scale_nt": scale_nt},
    )


@dataclass
class OnlineEllipsoid:
    """One-sample-at-a-time ellipsoid estimator (seed 002) by recursive least squares.

    Parameters
    ----------
    scale_nt
        Normalisation of readings (typical field magnitude) [nT]; keeps ``D`` well scaled.
    forgetting
        RLS forgetting factor λ ≤ 1 (1 = none); ``1 − 1/λ`` is the memory in samples.
    """

    scale_nt: float = 4.0e4
    forgetting: float = 1.0
    eta: FloatArray = field(default_factory=lambda: np.array([1, 1, 1, 0, 0, 0, 0, 0, 0, 0.0]))
    P: FloatArray = field(default_factory=lambda: np.eye(10) * 1e6)
    n_seen: int = 0
    mean_norm_nt: float = 0.0
    fixed_reference: bool = False
    info: FloatArray = field(default_factory=lambda: np.zeros((10, 10)))

    def update(self, m_nt: FloatArray, b_ref_mag_nt: float | None = None) -> None:
        """Absorb one reading ``m`` (3,) [nT] with its reference magnitude [nT] (or, as in the
        patent, the running mean of ‖m‖ when ``None``)."""
        m = np.asarray(m_nt, dtype=np.float64).reshape(3)
        if self.n_seen == 0:
            self.fixed_reference = b_ref_mag_nt is None
            if self.fixed_reference:
                # a constant reference cannot separate the constant term from the scale:
                # keep η10 at 0 (the patent's nine parameters) and rescale in calibration()
                self.P[9, :] = 0.0
                self.P[:, 9] = 0.0
                self.eta[9] = 0.0
        self.n_seen += 1
        self.mean_norm_nt += (float(np.linalg.norm(m)) - self.mean_norm_nt) / self.n_seen
        ref = self.mean_norm_nt if b_ref_mag_nt is None else float(b_ref_mag_nt)
        d = ellipsoid_features(m, scale_nt=self.scale_nt)[0]
        y = (ref / self.scale_nt) ** 2
        self.info += np.outer(d, d)
        Pd = self.P @ d
        k = Pd / (self.forgetting + d @ Pd)
        self.eta = self.eta + k * (y - d @ self.eta)
        self.P = (self.P - np.outer(k, Pd)) / self.forgetting

    def condition_number(self) -> float:
        """Condition number of the samples' design ``D`` (column-equilibrated), from ``Σ d dᵀ``."""
        k = 9 if self.fixed_reference else 10
        S = self.info[:k, :k]
        dg = np.sqrt(np.diag(S))
        if np.any(dg == 0):
            return float("inf")
        w = np.linalg.eigvalsh(S / np.outer(dg, dg))
        return float(np.sqrt(w[-1] / w[0])) if w[0] > 0 else float("inf")

    def calibration(self) -> AffineCalibration:
        """The current calibration (patent steps 9-10).

        With the running-mean reference the fitted quadric is ``(m − X0)ᵀA(m − X0) = R̄² + X0ᵀAX0``
        (scaled units), so ``G`` is rescaled to give ``‖G (m − X0)‖ = R̄``.
        """
        cond = self.condition_number()
        if not cond < CONDITION_LIMIT:
            raise PoorCoverageError("online", cond, CONDITION_LIMIT)
        cal = eta_to_calibration(self.eta, scale_nt=self.scale_nt)
        cal.extra["condition_number"] = cond
        if self.fixed_reference:
            x0 = cal.o / self.scale_nt
            r2 = (self.mean_norm_nt / self.scale_nt) ** 2
            A = cal.M.T @ cal.M
            cal.M = cal.M * np.sqrt(r2 / (r2 + float(x0 @ A @ x0)))
        return cal


def fit_online(data: FitData, *, forgetting: float = 1.0) -> AffineCalibration:
    """Run :class:`OnlineEllipsoid` over the samples in order and return its final calibration.

    Uses the per-sample reference magnitude when the data carry one, else the running mean of ‖m‖.
    """
    if data.n < 20:
        raise TooFewSamplesError("online", data.n, 20)
    ref = data.b_ref_mag_nt
    scale = (
        float(np.median(ref))
        if ref is not None
        else float(np.median(np.linalg.norm(data.b_raw_nt, axis=1)))
    )
    est = OnlineEllipsoid(scale_nt=scale, forgetting=forgetting)
    for i in range(data.n):
        est.update(data.b_raw_nt[i], None if ref is None else float(ref[i]))
    return est.calibration()


@dataclass(frozen=True)
class RetrainEvent:
    """One periodic retraining: at ``t_s`` on the window ``[t_s − window_s, t_s)``."""

    t_s: float
    n_samples: int
    calibration: Calibration


@dataclass
class PeriodicRetrainer:
    """Sliding-window periodic retraining with warm start (Wang et al. 2020, section 4).

    Parameters
    ----------
    fit
        ``fit(window_data, warm_start) -> Calibration``; ``warm_start`` is the calibration in
        service (``None`` before the first).
    window_s
        Length of the sliding window [s].
    period_s
        Interval between retrainings [s].
    min_samples
        Skip a retraining whose window holds fewer samples.
    """

    fit: Callable[[FitData, Calibration | None], Calibration]
    window_s: float
    period_s: float
    min_samples: int = 10
    events: list[RetrainEvent] = field(default_factory=list)

    def run(
        self,
        t_s: FloatArray,
        data: FitData,
        *,
        initial: Calibration | None = None,
        t_first_s: float | None = None,
    ) -> list[RetrainEvent]:
        """Retrain every ``period_s`` from ``t_first_s`` (default ``t_s[0] + window_s``) on."""
        t = np.asarray(t_s, dtype=np.float64)
        current = initial
        t_fit = t[0] + self.window_s if t_first_s is None else t_first_s
        while t_fit <= t[-1]:
            mask = (t >= t_fit - self.window_s) & (t < t_fit)
            if int(mask.sum()) >= self.min_samples:
                current = self.fit(data.subset(mask), current)
                self.events.append(RetrainEvent(float(t_fit), int(mask.sum()), current))
            t_fit += self.period_s
        return self.events

    def apply(
        self,
        t_s: FloatArray,
        b_raw_nt: FloatArray,
        x_hk: FloatArray | None = None,
        *,
        initial: Calibration,
    ) -> FloatArray:
        """Calibrate each sample with the calibration in service at its time."""
        t = np.asarray(t_s, dtype=np.float64)
        out = initial.apply(b_raw_nt, x_hk)
        for ev in self.events:
            sel = t >= ev.t_s
            if np.any(sel):
                out[sel] = ev.calibration.apply(
                    b_raw_nt[sel], None if x_hk is None else np.asarray(x_hk)[sel]
                )
        return out
