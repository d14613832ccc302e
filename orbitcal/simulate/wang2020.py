"""The simulation scenarios of Wang et al. (2020), as pure functions returning arrays.

* truth, eq. 16: ``B(t) = 4000 + 100 · [sin t, cos t, −sin t]`` nT (t in seconds);
* ground scenario: the eq. 15 sensor (A, B_0) with white noise σ = 2 nT;
* orbit scenario: eq. 15 up to ``t = 15 s``, then the eq. 17 parameters ("affected by the space
  environment at t = 15 s").

Wang, Y.K., Sheng, T., He, L. and Cheng, Z.Y. (2020) Calibration Method of Magnetometer Based on BP
Neural Network. J. Computer and Communications 8, 31-41. doi:10.4236/jcc.2020.86004.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.sensor import WANG2020_NOISE_STD_NT, SensorModel

__all__ = [
    "WANG2020_CHANGE_T_S",
    "Wang2020Scenario",
    "wang2020_ground",
    "wang2020_orbit",
    "wang2020_time_s",
    "wang2020_truth_nt",
]


#: Wang 2020 section 5: the sensor parameters change at t = 15 s (eq. 17).
WANG2020_CHANGE_T_S = 15.0


@dataclass(frozen=True)
class Wang2020Scenario:
    """Arrays of one scenario.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Time since the start [s].
    b_true_nt : ndarray, shape (N, 3)
        True field, eq. 16 [nT].
    b_meas_nt : ndarray, shape (N, 3)
        Magnetometer output, eq. 1 [nT].
    changed : ndarray of bool, shape (N,)
        True where the eq. 17 parameters apply.
    """

    t_s: FloatArray
    b_true_nt: FloatArray
    b_meas_nt: FloatArray
    changed: npt.NDArray[np.bool_]


def wang2020_time_s(*, duration_s: float = 30.0, step_s: float = 0.01) -> FloatArray:
    """A uniform time grid ``0, step, …, < duration`` [s] (the paper does not state its own)."""
    return np.arange(0.0, duration_s, step_s)


def wang2020_truth_nt(t_s: npt.ArrayLike) -> FloatArray:
    """Eq. 16: ``4000 + 100 · [sin t, cos t, −sin t]`` [nT], shape (N, 3)."""
    t = np.asarray(t_s, dtype=np.float64)
    return 4000.0 + 100.0 * np.stack([np.sin(t), np.cos(t), -np.sin(t)], axis=-1)


def wang2020_ground(
    t_s: npt.ArrayLike, *, rng: np.random.Generator, noise_std_nt: float = WANG2020_NOISE_STD_NT
) -> Wang2020Scenario:
    """Ground scenario: eq. 16 truth through the eq. 15 sensor with σ = 2 nT noise.

    Parameters
    ----------
    t_s : array_like, shape (N,)
        Times [s].
    rng : numpy.random.Generator
        Seeded noise source.
    noise_std_nt : float
        Noise standard deviation per axis [nT].
    """
    t = np.asarray(t_s, dtype=np.float64)
    b = wang2020_truth_nt(t)
    meas = SensorModel.from_wang2020_ground(noise_std_nt=noise_std_nt).measure(b, rng=rng)
    return Wang2020Scenario(t, b, meas, np.zeros(t.shape, dtype=bool))


def wang2020_orbit(
    t_s: npt.ArrayLike,
    *,
    rng: np.random.Generator,
    t_change_s: float = WANG2020_CHANGE_T_S,
    noise_std_nt: float = WANG2020_NOISE_STD_NT,
) -> Wang2020Scenario:
    """Orbit scenario: eq. 15 sensor for ``t ≤ t_change_s``, eq. 17 after it.

    Parameters
    ----------
    t_s : array_like, shape (N,)
        Times [s].
    rng : numpy.random.Generator
        Seeded noise source (one draw per sample and axis, as in :func:`wang2020_ground`).
    t_change_s : float
        Time of the parameter change [s] (15 s in the paper).
    noise_std_nt : float
        Noise standard deviation per axis [nT].
    """
    t = np.asarray(t_s, dtype=np.float64)
    b = wang2020_truth_nt(t)
    changed = t > t_change_s
    ground = SensorModel.from_wang2020_ground(noise_std_nt=0.0).measure_noiseless(b)
    orbit = SensorModel.wang2020_orbit_change(noise_std_nt=0.0).measure_noiseless(b)
    meas = np.where(changed[:, None], orbit, ground)
    meas = meas + rng.normal(0.0, noise_std_nt, size=meas.shape)
    return Wang2020Scenario(t, b, meas, changed)
