"""The hidden layer of ``lmbp-hk`` stays only where it earns its place on later, unseen samples.

Regression: on a nadir Swarm A world (IGRF-14, σ = 5 nT, world seed 42) whose sensor is exactly
affine, an LM-BP network with housekeeping inputs left 47.9 nT on the held-out later block
against 4.93 nT for the 12-parameter fit: tanh units extrapolating in temperature and
magnetorquer inputs. The validation guard switches the hidden layer off there, and keeps it where
the sensor is not affine (a temperature-driven scale factor), where it beats linear + regressors.
"""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.orbit import Orbit
from orbitcal.pipeline import calibrate_telemetry
from orbitcal.reproduce.onorbit import orbit_world
from orbitcal.simulate.world import World


def _holdout(telemetry: object, orbit: Orbit, method: str) -> tuple[float, dict[str, object]]:
    cal, doc = calibrate_telemetry(
        telemetry,  # type: ignore[arg-type]
        orbit=orbit,
        method=method,
        rng=np.random.default_rng(0),
    )
    return float(doc["metrics"]["holdout_rms_nt"]), dict(getattr(cal, "training", {}))


def test_affine_sensor_on_nadir_orbit_gets_the_linear_solution() -> None:
    w = orbit_world(
        attitude="nadir", n_samples=2000, noise_std_nt=5.0, rng=np.random.default_rng(42)
    )
    orbit = Orbit.from_tle(w.tle)
    rms_lin, _ = _holdout(w.telemetry, orbit, "linear-hk")
    rms_net, training = _holdout(w.telemetry, orbit, "lmbp-hk")
    assert str(training["hidden_layer"]).startswith("off")
    assert rms_net == pytest.approx(rms_lin, rel=0.01)  # was 47.9 nT against 4.93 nT


def test_temperature_driven_scale_factor_keeps_the_network(
    swarm_a_temperature_world: tuple[World, Orbit],  # tests/conftest.py
) -> None:
    world, orbit = swarm_a_temperature_world
    rms_lin, _ = _holdout(world.telemetry, orbit, "linear-hk")
    rms_net, training = _holdout(world.telemetry, orbit, "lmbp-hk")
    assert str(training["hidden_layer"]).startswith("kept")
    assert rms_net < 0.7 * rms_lin  # measured 2.46 nT against 4.53 nT
