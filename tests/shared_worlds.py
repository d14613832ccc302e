"""Orbits, sensors and worlds that several test files share: one definition instead of copies.

Importable from every test (``tests/`` is on ``sys.path`` through its conftest); the fixtures of
``tests/conftest.py`` wrap what is costly to build, so it is built once per session.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.orbit import Orbit
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate.world import World

#: The real CelesTrak sets (Swarm A/B/C, ISS; provenance in tests/authorities/README.md).
REAL_TLES_FILE = Path(__file__).resolve().parent / "authorities" / "swarm_iss_real_tles.tle"
SWARM_A_NORAD = 39452


def _two_lines(norad_id: int, epoch_field: str) -> str:
    """The two lines of the set of ``norad_id`` whose line-1 epoch field is ``epoch_field``."""
    lines = REAL_TLES_FILE.read_text().splitlines()
    for k, line in enumerate(lines):
        if line.startswith(f"1 {norad_id:05d}") and line[18:32] == epoch_field:
            return f"{line}\n{lines[k + 1]}"
    raise LookupError(f"no set of {norad_id} with epoch {epoch_field} in {REAL_TLES_FILE}")


#: Swarm A, CelesTrak, epoch 2022-08-01T12:28:23.70Z: the orbit of the service and probe tests.
SWARM_A_2022_TLE = _two_lines(SWARM_A_NORAD, "22213.51971877")

#: The same element set as CelesTrak's JSON OMM.
SWARM_A_2022_OMM: dict[str, Any] = {
    "OBJECT_NAME": "SWARM A",
    "OBJECT_ID": "2013-067B",
    "EPOCH": "2022-08-01T12:28:23.701728",
    "MEAN_MOTION": 15.32769581,
    "ECCENTRICITY": 0.0002354,
    "INCLINATION": 87.3611,
    "RA_OF_ASC_NODE": 208.4349,
    "ARG_OF_PERICENTER": 100.1496,
    "MEAN_ANOMALY": 260.0021,
    "EPHEMERIS_TYPE": 0,
    "CLASSIFICATION_TYPE": "U",
    "NORAD_CAT_ID": SWARM_A_NORAD,
    "ELEMENT_SET_NO": 999,
    "REV_AT_EPOCH": 48883,
    "BSTAR": 5.0768e-05,
    "MEAN_MOTION_DOT": 1.645e-05,
    "MEAN_MOTION_DDOT": 0,
}


def swarm_class_sensor(rng: np.random.Generator) -> SensorModel:
    """A vector fluxgate of the Swarm class: 1 % scale/misalignment, 50 nT biases, 0.5 nT noise.

    Draws from ``rng`` (the caller goes on using it for the world).
    """
    from orbitcal.sensor import SensorModel

    return SensorModel(
        a_matrix=np.eye(3) + rng.normal(scale=0.01, size=(3, 3)),
        bias_nt=rng.normal(scale=50.0, size=3),
        noise_std_nt=0.5,
    )


def swarm_a_temperature_world(noise_std_nt: float = 2.0) -> tuple[World, Orbit]:
    """Swarm A's latest real set, tumbling, 20 000 s at 10 s, temperature and magnetorquer
    effects (the simulator's temperature effect drifts the scale factor too), a random sensor."""
    from orbitcal.orbit import Orbit
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import attitude_profile, make_effect, simulate_world
    from orbitcal.simulate.world import select_tle

    tle = select_tle(REAL_TLES_FILE.read_text(), norad_id=SWARM_A_NORAD)
    orbit = Orbit.from_tle(f"{tle.name}\n{tle.line1}\n{tle.line2}")
    world = simulate_world(
        tle,
        start_utc_s=orbit.epoch_utc_s,
        duration_s=20_000.0,
        cadence_s=10.0,
        rng=np.random.default_rng(7),
        attitude=attitude_profile("tumbling"),
        sensor=SensorModel.random(rng=np.random.default_rng(8), noise_std_nt=noise_std_nt),
        effects=[make_effect("temperature"), make_effect("magnetorquer")],
    )
    return world, orbit


def simulated_report(
    tmp_path: Path, effect: str, *, attitude: str, seed: int = 5, noise_std_nt: float | None = None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """``orbitcal diagnose``'s report (defaults) of four orbits of Swarm A at 10 s from
    2023-07-05 with ``effect`` injected by ``orbitcal simulate`` (``NAME:k=v,...``), and the
    simulation's truth."""
    import json

    from orbitcal.cli import main

    world, out = tmp_path / "world", tmp_path / "report.json"
    argv = [
        "simulate", "--tle", str(REAL_TLES_FILE), "--norad", str(SWARM_A_NORAD),
        "--start", "2023-07-05T00:00:00Z", "--duration-s", "22600", "--cadence-s", "10",
        "--attitude", attitude, "--effect", effect, "--seed", str(seed), "--out", str(world),
    ]  # fmt: skip
    if noise_std_nt is not None:
        argv += ["--noise-std-nt", f"{noise_std_nt:g}"]
    assert main(argv) == 0
    table, tle = world / "telemetry.csv", world / "spacecraft.tle"
    assert main(["diagnose", str(table), "--tle", str(tle), "--out", str(out)]) == 0
    return json.loads(out.read_text()), json.loads((world / "truth.json").read_text())
