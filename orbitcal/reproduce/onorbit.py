"""The on-orbit comparison scenario: a Swarm TLE, IGRF-14, a sensor with injectable effects.

A spacecraft on a real TLE (Swarm A, NORAD 39452, CelesTrak, ``tests/authorities``) flies a
tumbling or nadir-pointing attitude; the true field is IGRF-14 along the SGP4 track rotated into the
body frame by orbitcal's own truth pipeline; the magnetometer follows Wang et al. (2020) eq. 1,
``b_raw = A b + b0 + ε``, plus — when asked — a temperature-driven bias ``k_T (T − T0)`` and a
magnetorquer field ``K_mtq m`` (the housekeeping effects of CONTRACT section 5). The same table is
what a real spacecraft would send: times, raw field, quaternions, temperature, ``mtq_*``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from orbitcal.telemetry import Telemetry

__all__ = [
    "SWARM_A_TLE",
    "OrbitWorld",
    "orbit_world",
    "write_tle",
]

FloatArray = NDArray[np.float64]

# Swarm A (NORAD 39452), CelesTrak element set of 2022-08-01, copied verbatim from
# tests/authorities/swarm_iss_real_tles.tle (provenance in tests/authorities/README.md).
SWARM_A_TLE = """SWARM A
1 39452U 13067B   22213.51971877  .00001645  00000+0  50768-4 0  9990
2 39452  87.3611 208.4349 0002354 100.1496 260.0021 15.32769581488835"""


@dataclass(frozen=True)
class OrbitWorld:
    """A simulated telemetry table with everything the simulation knows.

    Attributes
    ----------
    telemetry
        The contract table (no positions: they come from the TLE).
    tle
        The TLE text used.
    b_true_body_nt
        True (reference) field in the body frame, ``(N, 3)`` [nT].
    a_matrix, bias_nt
        The sensor's ``A`` and ``b0`` [nT].
    k_hk_nt
        ``(3, k)`` housekeeping coupling [nT per regressor unit] in the order of
        ``Telemetry.regressors()`` (temperature first, then ``mtq_x..z``), zeros when absent.
    noise_std_nt
        σ of the white noise [nT].
    """

    telemetry: Telemetry
    tle: str
    b_true_body_nt: FloatArray
    a_matrix: FloatArray
    bias_nt: FloatArray
    k_hk_nt: FloatArray
    noise_std_nt: float


def orbit_world(
    *,
    attitude: str = "tumbling",
    n_samples: int = 2000,
    dt_s: float = 10.0,
    noise_std_nt: float = 5.0,
    temperature: bool = False,
    magnetorquer: bool = False,
    rng: np.random.Generator,
    tle: str = SWARM_A_TLE,
    a_matrix: FloatArray | None = None,
    bias_nt: FloatArray | None = None,
) -> OrbitWorld:
    """Simulate ``n_samples`` every ``dt_s`` from the TLE epoch.

    Parameters
    ----------
    attitude
        ``"tumbling"`` (constant skew body rate), ``"nadir"`` (LVLH) or ``"inertial"``.
    noise_std_nt
        White noise σ per axis [nT].
    temperature
        Sensor temperature swinging ±10 °C around 20 °C with the orbit (eclipse-like, with an
        orbit-to-orbit wander), coupled into the reading at ``k_T = [2.0, −1.5, 1.0]`` nT/°C.
    magnetorquer
        Piecewise-constant dipole commands (±8 A·m², changed every 2-5 min), coupled at ~10-40 nT
        per A·m².
    rng
        Seeded generator (noise, commands, sensor parameters when not given).
    a_matrix, bias_nt
        Sensor ``A`` and ``b0`` [nT]; default: a random plausible fluxgate (3 % scale, 0.5°
        misalignment, 500 nT bias).
    """
    from orbitcal.frames import itrs_to_gcrs
    from orbitcal.orbit import Orbit
    from orbitcal.simulate.attitude_profiles import attitude_profile
    from orbitcal.truth import truth_body_nt

    orbit = Orbit.from_tle(tle)
    t = orbit.epoch_utc_s + dt_s * np.arange(n_samples, dtype=np.float64)
    eph = orbit.propagate(t).require_valid()
    r_gcrs = itrs_to_gcrs(eph.r_itrs_km, t)
    omega = np.array([0.0, 0.0, 7.2921150e-5])  # Earth rotation [rad/s] (IERS)
    v_gcrs = itrs_to_gcrs(eph.v_itrs_km_s + np.cross(omega, eph.r_itrs_km), t)
    profile = attitude_profile(attitude)
    q = profile.q_wxyz(t, r_gcrs, v_gcrs)
    b_true = truth_body_nt(t, eph.r_itrs_km, q, attitude_frame="GCRS", field="IGRF-14")

    if a_matrix is None:
        scale = np.diag(1.0 + rng.normal(0.0, 0.03, 3))
        mis = np.deg2rad(0.5) * rng.normal(size=(3, 3))
        np.fill_diagonal(mis, 0.0)
        a_matrix = scale @ (np.eye(3) + mis)
    if bias_nt is None:
        bias_nt = rng.normal(0.0, 500.0, 3)
    A = np.asarray(a_matrix, dtype=np.float64)
    b0 = np.asarray(bias_nt, dtype=np.float64)
    b_raw = b_true @ A.T + b0 + rng.normal(0.0, noise_std_nt, size=b_true.shape)

    k_cols: list[FloatArray] = []
    temperature_c = None
    mtq = None
    if temperature:
        period_s = 5700.0
        phase = 2 * np.pi * (t - t[0]) / period_s
        temperature_c = 20.0 + 10.0 * np.sin(phase) + 2.0 * np.sin(phase / 7.3)
        k_t = np.array([2.0, -1.5, 1.0])
        b_raw = b_raw + np.outer(temperature_c - 20.0, k_t)
        k_cols.append(k_t[:, None])
    if magnetorquer:
        mtq = np.zeros((n_samples, 3))
        i = 0
        while i < n_samples:
            span = int(rng.integers(max(1, int(120 / dt_s)), max(2, int(300 / dt_s))))
            mtq[i : i + span] = rng.uniform(-8.0, 8.0, 3)
            i += span
        K_mtq = rng.uniform(10.0, 40.0, (3, 3)) * rng.choice([-1.0, 1.0], (3, 3))
        b_raw = b_raw + mtq @ K_mtq.T
        k_cols.append(K_mtq)
    k_hk = np.hstack(k_cols) if k_cols else np.zeros((3, 0))
    tel = Telemetry(
        t_utc_s=t,
        b_raw_nt=b_raw,
        q_wxyz=q,
        temperature_c=temperature_c,
        mtq_am2=mtq,
    )
    return OrbitWorld(tel, tle, b_true, A, b0, k_hk, float(noise_std_nt))


def write_tle(path: str | Path, tle: str = SWARM_A_TLE) -> Path:
    """Write the TLE text to ``path`` (for CLI runs); returns the path."""
    p = Path(path)
    p.write_text(tle + "\n", encoding="ascii")
    return p
