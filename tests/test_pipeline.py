"""On-orbit must-shows through orbitcal's own pipeline: a Swarm A TLE, SGP4, IGRF-14, held-out
later blocks. Telemetry has no positions, so truth comes from the TLE like in operations."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orbitcal.calibrate import MissingAttitudeError, UnknownMethodError
from orbitcal.calibrate.document import REQUIRED_KEYS
from orbitcal.orbit import Orbit
from orbitcal.pipeline import apply_document, calibrate_telemetry
from orbitcal.reproduce.onorbit import OrbitWorld, orbit_world
from orbitcal.simulate.world import World
from orbitcal.telemetry import Telemetry

SIGMA_NT = 5.0


def _fit(world: OrbitWorld, method: str, **kw: object) -> tuple[object, dict]:  # type: ignore[type-arg]
    return calibrate_telemetry(
        world.telemetry,
        orbit=Orbit.from_tle(world.tle),
        method=method,
        rng=np.random.default_rng(0),
        **kw,  # type: ignore[arg-type]
    )


@pytest.fixture(scope="module")
def clean_world() -> OrbitWorld:
    return orbit_world(
        attitude="tumbling", n_samples=2000, noise_std_nt=SIGMA_NT, rng=np.random.default_rng(41)
    )


@pytest.fixture(scope="module")
def effects_world() -> OrbitWorld:
    return orbit_world(
        attitude="tumbling",
        n_samples=2000,
        noise_std_nt=SIGMA_NT,
        temperature=True,
        magnetorquer=True,
        rng=np.random.default_rng(42),
    )


def test_pipeline_truth_matches_the_simulation(clean_world: OrbitWorld) -> None:
    from orbitcal.pipeline import fit_data_for_telemetry

    data, name = fit_data_for_telemetry(
        clean_world.telemetry, orbit=Orbit.from_tle(clean_world.tle)
    )
    assert name == "IGRF-14"
    assert data.b_ref_body_nt is not None
    np.testing.assert_allclose(data.b_ref_body_nt, clean_world.b_true_body_nt, atol=1e-6)


def test_linear_at_noise_floor_and_lmbp_within_5_percent(clean_world: OrbitWorld) -> None:
    _, lin = _fit(clean_world, "linear")
    _, net = _fit(clean_world, "lmbp-hk")
    h_lin = lin["metrics"]["holdout_rms_nt"]
    h_net = net["metrics"]["holdout_rms_nt"]
    # σ per axis plus the fit's σ·√(4/N) (NOTES): noise floor within 5 %
    assert h_lin < 1.05 * SIGMA_NT
    assert h_net < 1.05 * h_lin, (h_net, h_lin)
    assert lin["metrics"]["n_holdout"] == 500


def test_with_temperature_and_magnetorquer(effects_world: OrbitWorld) -> None:
    """LM-BP with housekeeping inputs matches linear + regressors; the paper's raw-input network
    cannot see the cause and fails (a finding, reported in benchmarks/results/lm.md)."""
    _, lin = _fit(effects_world, "linear")
    _, lin_hk = _fit(effects_world, "linear-hk")
    _, net_hk = _fit(effects_world, "lmbp-hk")
    _, net_raw = _fit(effects_world, "lmbp")
    h = {
        k: d["metrics"]["holdout_rms_nt"]
        for k, d in {"linear": lin, "linear-hk": lin_hk, "lmbp-hk": net_hk, "lmbp": net_raw}.items()
    }
    assert h["linear-hk"] < 1.05 * SIGMA_NT, h
    assert h["lmbp-hk"] < 1.05 * h["linear-hk"], h
    assert h["lmbp"] > 10 * SIGMA_NT, h  # raw inputs only: the effects stay in the residual
    assert h["linear"] > 10 * SIGMA_NT, h
    assert net_hk["model"]["hk_names"] == ["temperature", "mtq_x", "mtq_y", "mtq_z"]


def test_document_keys_and_apply_round_trip(effects_world: OrbitWorld) -> None:
    cal, doc = _fit(effects_world, "lmbp-hk", spacecraft="swarm-a", version=7)
    assert set(REQUIRED_KEYS) <= set(doc)
    assert doc["spacecraft"] == "swarm-a" and doc["version"] == 7
    assert doc["reference_field"] == "IGRF-14"
    assert doc["data"]["n"] == 2000 and doc["data"]["start"].endswith("Z")
    assert np.asarray(doc["linear"]["M"]).shape == (3, 3) and len(doc["linear"]["o"]) == 3
    back = json.loads(json.dumps(doc))
    x_hk, _ = effects_world.telemetry.regressors()
    direct = cal.apply(effects_world.telemetry.b_raw_nt, x_hk)  # type: ignore[attr-defined]
    assert np.array_equal(apply_document(back, effects_world.telemetry), direct)
    # the linear block of a linear method is the calibration itself
    lin_cal, lin_doc = _fit(effects_world, "linear-hk")
    np.testing.assert_array_equal(np.asarray(lin_doc["linear"]["M"]), lin_cal.M)  # type: ignore[attr-defined]


def test_scalar_method_without_attitude_and_vector_method_refuses(clean_world: OrbitWorld) -> None:
    tel = clean_world.telemetry
    no_q = Telemetry(t_utc_s=tel.t_utc_s, b_raw_nt=tel.b_raw_nt)
    world = OrbitWorld(
        no_q,
        clean_world.tle,
        clean_world.b_true_body_nt,
        clean_world.a_matrix,
        clean_world.bias_nt,
        clean_world.k_hk_nt,
        clean_world.noise_std_nt,
    )
    _, doc = _fit(world, "twostep")
    assert doc["metrics"]["holdout_rms_nt"] < 1.08 * SIGMA_NT  # scalar residual at noise floor
    assert "holdout_norm_rms_nt" not in doc["metrics"]
    with pytest.raises(MissingAttitudeError, match="attitude"):
        _fit(world, "linear")
    with pytest.raises(UnknownMethodError, match="known"):
        _fit(clean_world, "magic")


def test_lmbp_beats_linear_regressors_on_the_simulators_temperature_scale_drift(
    swarm_a_temperature_world: tuple[World, Orbit],  # tests/conftest.py
) -> None:
    """orbitcal.simulate's temperature effect drifts the scale factor too (dB = k_b ΔT +
    k_s ⊙ B ΔT): a product that additive regressors cannot represent and the network with
    housekeeping inputs learns. Built with the project's simulator on the real Swarm A TLE."""
    world, orbit = swarm_a_temperature_world
    sigma = 2.0  # the world's sensor noise per axis [nT]
    h = {}
    for method in ("linear-hk", "lmbp-hk"):
        _, doc = calibrate_telemetry(
            world.telemetry, orbit=orbit, method=method, rng=np.random.default_rng(0)
        )
        h[method] = doc["metrics"]["holdout_rms_nt"]
    assert h["lmbp-hk"] < 0.75 * h["linear-hk"], h
    assert h["lmbp-hk"] < 1.4 * sigma, h
