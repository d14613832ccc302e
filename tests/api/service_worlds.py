"""Synthetic telemetry for the service tests: known sensor parameters on a real orbit.

The reference field comes from the library (``orbitcal.truth.truth_body_nt``, IGRF-14); the raw
readings are ``b_raw = inv(M) @ b_body + o + noise`` so that the calibration
``b_cal = M @ (b_raw - o)`` is known exactly. Positions come from SGP4 on a real Swarm A TLE
(CelesTrak, epoch 2022-08-01, ``tests/authorities/swarm_iss_real_tles.tle``) — the service
computes them from the same TLE — and the attitude is a slow tumble, so all 12 parameters are
observable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation
from shared_worlds import SWARM_A_2022_TLE

from orbitcal.orbit import Orbit
from orbitcal.truth import truth_body_nt

#: Swarm A (NORAD 39452), CelesTrak, epoch 2022-08-01T12:28Z (tests/shared_worlds.py).
SWARM_A_TLE = SWARM_A_2022_TLE

T0_UTC_S = 1_659_312_000.0  # 2022-08-01T00:00:00Z


@dataclass(frozen=True)
class Sensor:
    M: np.ndarray  # (3, 3) calibration matrix
    o: np.ndarray  # (3,) offset [nT]
    noise_nt: float

    def raw(self, b_body_nt: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        clean = b_body_nt @ np.linalg.inv(self.M).T + self.o
        return clean + rng.normal(0.0, self.noise_nt, clean.shape)


SENSOR_A = Sensor(
    M=np.array([[1.02, 0.01, -0.005], [0.0, 0.98, 0.02], [0.0, 0.0, 1.01]]),
    o=np.array([120.0, -80.0, 45.0]),
    noise_nt=2.0,
)
#: After the "parameter change" (as in Wang et al. 2020): other gains and a large offset jump.
SENSOR_B = Sensor(
    M=np.array([[0.97, -0.02, 0.01], [0.0, 1.03, -0.01], [0.0, 0.0, 0.99]]),
    o=np.array([-300.0, 250.0, 180.0]),
    noise_nt=2.0,
)


def trajectory(t_utc_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(N, 3)`` ITRS [km] (SGP4, Swarm A) and attitudes ``(N, 4)`` (w, x, y, z)."""
    dt = t_utc_s - T0_UTC_S
    eph = Orbit.from_tle(SWARM_A_TLE).propagate(t_utc_s)
    assert not np.any(eph.error_code)
    r = np.asarray(eph.r_itrs_km)
    rotvec = np.stack([dt * 2e-3, dt * 1.3e-3 + 0.4, np.full_like(dt, 0.7) + dt * 0.7e-3], axis=-1)
    xyzw = Rotation.from_rotvec(rotvec).as_quat()
    q_wxyz = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    return r, q_wxyz


def world(
    start_utc_s: float,
    n: int,
    *,
    dt_s: float = 10.0,
    sensor: Sensor = SENSOR_A,
    seed: int = 0,
    positions: bool = True,
) -> tuple[pd.DataFrame, np.ndarray]:
    """A telemetry table (CONTRACT section-1 columns) and the true ``b_body_nt`` ``(N, 3)``.

    ``positions=False`` leaves out ``r_x, r_y, r_z`` (the service then propagates the TLE).
    """
    rng = np.random.default_rng(seed)
    t = start_utc_s + dt_s * np.arange(n)
    r, q = trajectory(t)
    b_body = truth_body_nt(t, r, q, attitude_frame="GCRS", field="IGRF-14")
    b_raw = sensor.raw(b_body, rng)
    df = pd.DataFrame(
        {
            "time": t,
            "b_x": b_raw[:, 0],
            "b_y": b_raw[:, 1],
            "b_z": b_raw[:, 2],
            "q_w": q[:, 0],
            "q_x": q[:, 1],
            "q_y": q[:, 2],
            "q_z": q[:, 3],
            "r_x": r[:, 0],
            "r_y": r[:, 1],
            "r_z": r[:, 2],
        }
    )
    if not positions:
        df = df.drop(columns=["r_x", "r_y", "r_z"])
    return df, b_body


def document_for(sensor: Sensor, *, method: str = "linear") -> dict[str, Any]:
    """The section-4 document of a sensor's exact calibration (what an oracle would fit)."""
    from orbitcal.calibrate.base import AffineCalibration
    from orbitcal.calibrate.document import calibration_to_document

    return calibration_to_document(
        AffineCalibration(method, sensor.M, sensor.o),
        spacecraft="",
        version=0,
        reference_field="IGRF-14",
        t_start_utc_s=T0_UTC_S,
        t_end_utc_s=T0_UTC_S,
        n_samples=0,
        metrics={"holdout_rms_nt": float("nan")},
    )
