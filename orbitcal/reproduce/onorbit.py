"""The on-orbit comparison scenario, built with the team's simulator (:mod:`orbitcal.simulate`).

A spacecraft on a real TLE (Swarm A, NORAD 39452, CelesTrak, ``tests/authorities``) flies a
tumbling or nadir-pointing attitude profile; :func:`orbitcal.simulate.simulate_world` propagates
it, evaluates IGRF-14 along the track in body axes, produces the housekeeping (orbital thermal
cycle, B-dot magnetorquer commands), injects the catalogue's ``temperature`` and ``magnetorquer``
effects when asked, and measures through :class:`orbitcal.sensor.SensorModel` (Wang et al. 2020
eq. 1). This module only chooses the scenario's parameters and keeps the comparison's view of the
result (:class:`OrbitWorld`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.telemetry import Telemetry

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.simulate.effects import Effect

__all__ = [
    "SWARM_A_TLE",
    "TEMPERATURE_BIAS_NT_PER_C",
    "OrbitWorld",
    "orbit_world",
    "write_tle",
]


# Swarm A (NORAD 39452), CelesTrak element set of 2023-11-19, copied verbatim from
# tests/authorities/swarm_iss_real_tles.tle (provenance in tests/authorities/README.md). An eclipse
# season: the simulator's orbital thermal cycle swings 11-31 °C. (The 2022-08-01 sets there are
# eclipse-free: the temperature stays within 1 °C and its coupling is not observable.)
SWARM_A_TLE = """SWARM A
1 39452U 13067B   23323.56602589  .00004670  00000+0  16430-3 0  9997
2 39452  87.3479  38.6206 0002885 107.3945 252.7620 15.29072398561541"""

#: Temperature coefficient of the offset in this scenario, body axes [nT/°C].
TEMPERATURE_BIAS_NT_PER_C: tuple[float, float, float] = (2.0, -1.5, 1.0)
#: Magnetorquer saturation dipole of this scenario's spacecraft [A·m²].
MTQ_MAX_AM2 = 8.0


@dataclass(frozen=True)
class OrbitWorld:
    """A simulated telemetry table with everything the simulation knows.

    Attributes
    ----------
    telemetry
        The contract table (no positions: they come from the TLE): times, raw field, quaternions
        and, when an effect couples to them, ``temperature`` and ``mtq_x..z``.
    tle
        The TLE text used.
    b_true_body_nt
        Reference field (IGRF-14) in the body frame, ``(N, 3)`` [nT]: the calibration target.
    a_matrix, bias_nt
        The sensor's ``A`` and ``b0`` [nT].
    k_hk_nt
        ``(3, k)`` housekeeping coupling in raw-reading space [nT per regressor unit] in the order
        of ``Telemetry.regressors()`` (temperature first, then ``mtq_x..z``): ``A [k_b | C]``, the
        ``K`` of ``b_raw = A b + b0 + K x_hk`` (:mod:`orbitcal.calibrate.linear`).
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
    """Simulate ``n_samples`` every ``dt_s`` from the TLE epoch with ``orbitcal.simulate``.

    Parameters
    ----------
    attitude
        Profile name of :func:`orbitcal.simulate.attitude_profile`: ``"tumbling"``, ``"nadir"``
        or ``"inertial"``.
    noise_std_nt
        White noise σ per axis [nT].
    temperature
        Inject the catalogue's ``temperature`` effect (driven by the simulator's orbital thermal
        cycle, ±10 °C in eclipse seasons) with offset coefficients
        :data:`TEMPERATURE_BIAS_NT_PER_C` and **no scale-factor term** (``scale_per_c = 0``):
        the effect is then exactly an additive regressor, as the comparison "LM-BP with
        housekeeping vs linear + the same regressors" states. (The simulator's default also
        drifts the scale factor, ``k_s ⊙ B ΔT``, which additive regressors cannot represent;
        ``benchmarks/lm.py`` and ``tests/test_pipeline.py`` show that case separately.) Adds the
        ``temperature`` column.
    magnetorquer
        Inject the catalogue's ``magnetorquer`` effect on the simulator's gated B-dot commands
        (saturation :data:`MTQ_MAX_AM2` A·m²), coupling 10–40 nT per A·m² with random signs drawn
        from ``rng``. Adds the ``mtq_x, mtq_y, mtq_z`` columns.
    rng
        Seeded generator: sensor parameters (when not given), couplings, and the simulator's
        own generator (housekeeping, noise) are all drawn from it.
    tle
        TLE text (two or three lines).
    a_matrix, bias_nt
        Sensor ``A`` and ``b0`` [nT]; default ``SensorModel.random`` (3 % scale, 0.5°
        misalignment, 500 nT bias).

    Notes
    -----
    Columns a spacecraft would send but nothing here couples to (the solar-array current, and
    temperature / magnetorquer commands when their effect is off) are left out of the table, so
    the ``-hk`` methods see exactly the regressors of the injected effects.
    """
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import attitude_profile, simulate_world
    from orbitcal.simulate.world import Housekeeping, parse_tles

    tle_set = parse_tles(tle)[0]
    random_sensor = SensorModel.random(rng=rng, noise_std_nt=noise_std_nt)
    sensor = SensorModel(
        a_matrix=random_sensor.a_matrix if a_matrix is None else np.asarray(a_matrix),
        bias_nt=random_sensor.bias_nt if bias_nt is None else np.asarray(bias_nt),
        noise_std_nt=noise_std_nt,
    )
    effects, k_cols = _housekeeping_effects(
        temperature=temperature, magnetorquer=magnetorquer, rng=rng
    )
    world = simulate_world(
        tle_set,
        start_utc_s=tle_set.epoch_utc_s,
        duration_s=n_samples * dt_s,
        cadence_s=dt_s,
        rng=rng,
        attitude=attitude_profile(attitude),
        sensor=sensor,
        effects=effects,
        housekeeping=Housekeeping(mtq_max_am2=MTQ_MAX_AM2),
    )
    tel = dataclasses.replace(
        world.telemetry,
        temperature_c=world.telemetry.temperature_c if temperature else None,
        mtq_am2=world.telemetry.mtq_am2 if magnetorquer else None,
        hk={},
    )
    k_hk = sensor.a_matrix @ np.hstack(k_cols) if k_cols else np.zeros((3, 0))
    return OrbitWorld(
        tel,
        tle,
        world.b_ref_body_nt,
        sensor.a_matrix,
        sensor.bias_nt,
        k_hk,
        float(noise_std_nt),
    )


def _housekeeping_effects(
    *, temperature: bool, magnetorquer: bool, rng: np.random.Generator
) -> tuple[list[Effect], list[FloatArray]]:
    """The temperature and magnetorquer effects :func:`orbit_world` injects, and the columns
    of the housekeeping matrix each adds (before the sensor matrix) [nT per unit]."""
    from orbitcal.simulate import make_effect

    effects: list[Effect] = []
    k_cols: list[FloatArray] = []
    if temperature:
        kb = np.asarray(TEMPERATURE_BIAS_NT_PER_C, dtype=np.float64)
        effects.append(
            make_effect("temperature", bias_nt_per_c=tuple(kb), scale_per_c=(0.0, 0.0, 0.0))
        )
        k_cols.append(kb[:, None])
    if magnetorquer:
        coupling = rng.uniform(10.0, 40.0, (3, 3)) * rng.choice([-1.0, 1.0], (3, 3))
        effects.append(make_effect("magnetorquer", coupling_nt_per_am2=tuple(coupling.reshape(-1))))
        k_cols.append(coupling)
    return effects, k_cols


def write_tle(path: str | Path, tle: str = SWARM_A_TLE) -> Path:
    """Write the TLE text to ``path`` (for CLI runs); returns the path."""
    p = Path(path)
    p.write_text(tle + "\n", encoding="ascii")
    return p
