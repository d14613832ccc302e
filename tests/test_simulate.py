"""Simulator: attitude profiles, the injected effects and their witnesses, determinism, output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from contract_doc import CONTRACT_EFFECTS
from scipy.spatial.transform import Rotation

from orbitcal.attitude import body_to_frame, frame_to_body
from orbitcal.frames import gcrs_to_itrs
from orbitcal.geomag import dipole_axis_itrs, magnetic_latitude_deg
from orbitcal.metrics import norm_rms_nt
from orbitcal.simulate import (
    EFFECT_NAMES,
    Housekeeping,
    Inertial,
    NadirLVLH,
    Tumbling,
    WorldState,
    kinematics,
    make_effect,
    parse_effect_spec,
    read_world,
    select_tle,
    simulate_world,
)
from orbitcal.telemetry import read_telemetry

START_UTC_S = pd.Timestamp("2023-07-05T00:00:00Z").timestamp()
SWARM_A = 39452


@pytest.fixture(scope="module")
def tle_text(real_tles_text: str) -> str:
    return real_tles_text  # tests/conftest.py


@pytest.fixture(scope="module")
def state(tle_text: str) -> WorldState:
    tle = select_tle(tle_text, norad_id=SWARM_A, at_utc_s=START_UTC_S)
    t = START_UTC_S + np.arange(0.0, 3 * 3600.0, 10.0)  # 3 h, two orbits
    kin = kinematics(tle, NadirLVLH(), t)
    return WorldState(
        tle=tle,
        attitude=NadirLVLH(),
        field="IGRF-14",
        kin=kin,
        housekeeping=Housekeeping(),
        hk_rng=np.random.default_rng(0),
    )


def _inject(state: WorldState, name: str, **params: object) -> tuple[np.ndarray, dict]:
    inj = make_effect(name, **params).inject(state, np.random.default_rng(1))
    assert inj.db_body_nt.shape == (len(state), 3)
    assert np.all(np.isfinite(inj.db_body_nt))
    return inj.db_body_nt, inj.info


def test_catalogue_names_are_the_contract_names() -> None:
    assert set(EFFECT_NAMES) == CONTRACT_EFFECTS


# --- attitude profiles ---------------------------------------------------------------------------


def test_nadir_body_z_points_to_the_earth_centre_in_gcrs(state: WorldState) -> None:
    z_gcrs = body_to_frame(np.array([0.0, 0.0, 1.0]), state.q_wxyz)
    r_hat = state.r_gcrs_km / np.linalg.norm(state.r_gcrs_km, axis=1, keepdims=True)
    np.testing.assert_allclose(z_gcrs, -r_hat, atol=1e-12)
    # the contract's scipy formula says the same: v_body = R(q).inv().apply(v_frame)
    q = state.q_wxyz
    r_body = Rotation.from_quat(q[:, [1, 2, 3, 0]]).inv().apply(r_hat)
    np.testing.assert_allclose(r_body, np.tile([0.0, 0.0, -1.0], (len(q), 1)), atol=1e-12)
    # body x follows the velocity within the flight-path angle of a near-circular orbit (< 0.1°)
    x_gcrs = body_to_frame(np.array([1.0, 0.0, 0.0]), q)
    v_hat = state.v_gcrs_km_s / np.linalg.norm(state.v_gcrs_km_s, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(np.sum(x_gcrs * v_hat, axis=1), -1, 1))).max() < 0.1
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


def test_inertial_and_tumbling_profiles(state: WorldState) -> None:
    t, r, v = state.t_utc_s, state.r_gcrs_km, state.v_gcrs_km_s
    q0 = (0.5, 0.5, -0.5, 0.5)
    qi = Inertial(q0_wxyz=q0).q_wxyz(t, r, v)
    np.testing.assert_allclose(qi, np.tile(q0, (t.size, 1)))
    rate = (0.6, -1.2, 1.5)
    qt = Tumbling(rate_body_deg_s=rate, q0_wxyz=q0).q_wxyz(t, r, v)
    np.testing.assert_allclose(qt[0], q0, atol=1e-12)
    # relative rotation between samples, in body axes, is ω·Δt
    rot = Rotation.from_quat(qt[:, [1, 2, 3, 0]])
    step = (rot[:-1].inv() * rot[1:]).as_rotvec()
    np.testing.assert_allclose(step, np.tile(np.deg2rad(rate) * 10.0, (t.size - 1, 1)), atol=1e-9)


# --- effects: magnitude and witness ------------------------------------------------------------


def test_temperature_follows_the_thermal_cycle(state: WorldState) -> None:
    temp = state.temperature_c
    assert 17.0 < temp.max() - temp.min() < 26.0  # ±10 °C sunlit/eclipse (plus albedo)
    warm, cold = temp[state.illumination > 0.5].mean(), temp[state.illumination < 0.5].mean()
    assert warm - cold > 8.0
    db, _ = _inject(state, "temperature")
    d_t = (temp - 20.0)[:, None]
    expected = (
        np.array([2.0, -1.5, 2.5]) * d_t
        + np.array([3e-5, -2e-5, 2.5e-5]) * state.b_ref_body_nt * d_t
    )
    np.testing.assert_allclose(db, expected, atol=1e-9)
    assert 10.0 < norm_rms_nt(db) < 60.0


def test_magnetorquer_coupling_is_recovered_from_the_commands(state: WorldState) -> None:
    m = state.mtq_am2
    assert np.abs(m).max() <= 2.0 + 1e-12 and np.abs(m).max() > 1.0
    db, _ = _inject(state, "magnetorquer")
    c_fit, *_ = np.linalg.lstsq(m, db, rcond=None)
    c = np.array([12.0, 2.0, -1.0, 1.5, -9.0, 3.0, -2.0, 1.0, 15.0]).reshape(3, 3)
    np.testing.assert_allclose(c_fit.T, c, atol=1e-9)
    assert 5.0 < norm_rms_nt(db) < 60.0


def test_time_offset_is_minus_delta_times_the_field_rate(state: WorldState) -> None:
    db, _ = _inject(state, "time_offset", offset_s=0.5)
    rate = np.gradient(state.b_ref_body_nt, state.t_utc_s, axis=0)
    np.testing.assert_allclose(db, -0.5 * rate, atol=0.05 * np.abs(0.5 * rate).max())
    assert 10.0 < norm_rms_nt(db) < 40.0  # NOTES: 1 s ≈ 37 nT mean along LEO; nadir rotation adds


def test_external_field_is_uniform_along_the_dipole_axis(state: WorldState) -> None:
    db, _ = _inject(state, "external_field", amplitude_nt=-80.0)
    from orbitcal.frames import itrs_to_gcrs

    db_itrs = gcrs_to_itrs(body_to_frame(db, state.q_wxyz), state.t_utc_s)
    np.testing.assert_allclose(
        db_itrs, np.tile(-80.0 * dipole_axis_itrs(), (len(state), 1)), atol=1e-6
    )
    assert itrs_to_gcrs is not None
    lat = np.degrees(np.arcsin(dipole_axis_itrs()[2]))
    assert 80.0 < lat < 81.5  # geomagnetic north pole, IGRF-14 2020 (orbitcal.geomag)


def test_crustal_field_has_the_known_size(state: WorldState) -> None:
    db, _ = _inject(state, "crustal_field", model="MF7")
    # NOTES: crust at 450 km is 2.5–3.5 nT rms, up to ~18 nT
    assert 1.5 < norm_rms_nt(db) < 6.0 and np.linalg.norm(db, axis=1).max() < 30.0


def test_sun_driven_is_zero_in_eclipse_and_follows_the_sun_in_body(state: WorldState) -> None:
    db, _ = _inject(state, "sun_driven")
    dark = state.illumination == 0.0
    assert dark.sum() > 50 and np.all(db[dark] == 0.0)
    lit = state.illumination == 1.0
    p = np.array([8.0, -3.0, 2.0, 4.0, 10.0, -5.0, -2.0, 6.0, 12.0]).reshape(3, 3)
    np.testing.assert_allclose(db[lit], state.sun_body_unit[lit] @ p.T, atol=1e-12)
    assert 5.0 < np.linalg.norm(db[lit], axis=1).mean() < 20.0


def test_nonlinearity_is_cubic(state: WorldState) -> None:
    db, _ = _inject(state, "nonlinearity")
    np.testing.assert_allclose(db, np.array([1e-12, -0.8e-12, 1.2e-12]) * state.b_ref_body_nt**3)
    assert 10.0 < norm_rms_nt(db) < 200.0


def test_orbit_error_along_track(state: WorldState, tle_text: str) -> None:
    db, info = _inject(state, "orbit_error", along_track_km=2.0)
    assert info["along_track_km_mean"] == pytest.approx(2.0, abs=0.02)
    assert 5.0 < norm_rms_nt(db) < 60.0
    # the true orbit from a later real TLE of the same spacecraft
    later = select_tle(tle_text, norad_id=SWARM_A, at_utc_s=START_UTC_S + 20 * 86400)
    assert later.epoch_utc_s > state.tle.epoch_utc_s + 3 * 86400
    db2, info2 = _inject(state, "orbit_error", true_tle=later.text)
    # a 3.7-day-old Swarm A TLE is off along track by about a kilometre or more
    assert 0.3 < abs(info2["along_track_km_mean"]) < 30.0
    assert np.all(np.isfinite(db2))


def test_parameter_drift_steps_half_way(state: WorldState) -> None:
    db, info = _inject(state, "parameter_drift", trend_nt_per_day=0.0)
    after = state.t_utc_s >= info["step_utc_s"]
    np.testing.assert_allclose(db[after], np.tile([15.0, -10.0, 8.0], (after.sum(), 1)))
    np.testing.assert_allclose(db[~after], 0.0)
    assert 0.45 < after.mean() < 0.55


def test_field_aligned_currents_at_high_magnetic_latitude_transverse_to_b(
    state: WorldState,
) -> None:
    db, _ = _inject(state, "field_aligned_currents")
    mlat = np.abs(magnetic_latitude_deg(state.r_itrs_km))
    assert np.all(db[mlat < 55.0] == 0.0)
    assert 100.0 < np.linalg.norm(db, axis=1).max() < 500.0
    b_hat = state.b_ref_body_nt / np.linalg.norm(state.b_ref_body_nt, axis=1, keepdims=True)
    np.testing.assert_allclose(np.sum(db * b_hat, axis=1), 0.0, atol=1e-8)


def test_attitude_error_leaves_the_scalar_field_clean(state: WorldState) -> None:
    db, info = _inject(state, "attitude_error", amplitude_deg=0.05)
    b = state.b_ref_body_nt
    np.testing.assert_allclose(
        np.linalg.norm(b + db, axis=1), np.linalg.norm(b, axis=1), rtol=1e-12
    )
    assert 0.02 < info["angle_deg_rms"] < 0.1
    assert 10.0 < norm_rms_nt(db) < 80.0  # 0.05° × 40 000 nT ≈ 35 nT


def test_effect_specs_and_errors() -> None:
    e = parse_effect_spec("temperature:bias_nt_per_c=1/2/3,t_ref_c=15")
    assert e.params == {
        "bias_nt_per_c": [1.0, 2.0, 3.0],
        "scale_per_c": [3e-5, -2e-5, 2.5e-5],
        "t_ref_c": 15,
    }
    assert parse_effect_spec("time_offset:offset_s=1.5").params == {"offset_s": 1.5}
    assert parse_effect_spec("time_offset:magnitude=4").params == {"offset_s": 2.0}
    assert parse_effect_spec("nonlinearity:cubic_per_nt2=2e-12").params["cubic_per_nt2"] == [2e-12]
    with pytest.raises(ValueError, match="unknown effect 'wobble'"):
        parse_effect_spec("wobble")
    with pytest.raises(ValueError, match="no parameter 'speed'"):
        parse_effect_spec("time_offset:speed=3")


# --- worlds ------------------------------------------------------------------------------------


def _world(tle_text: str, seed: int, **kw: object):
    return simulate_world(
        tle_text,
        norad_id=SWARM_A,
        start_utc_s=START_UTC_S,
        duration_s=1800.0,
        cadence_s=10.0,
        rng=np.random.default_rng(seed),
        seed=seed,
        **kw,
    )


def test_worlds_are_deterministic_by_seed(tle_text: str) -> None:
    effects = [make_effect("field_aligned_currents"), make_effect("attitude_error")]
    a = _world(tle_text, 5, effects=effects, attitude=Tumbling())
    b = _world(tle_text, 5, effects=effects, attitude=Tumbling())
    c = _world(tle_text, 6, effects=effects, attitude=Tumbling())
    np.testing.assert_array_equal(a.telemetry.b_raw_nt, b.telemetry.b_raw_nt)
    np.testing.assert_array_equal(a.telemetry.mtq_am2, b.telemetry.mtq_am2)
    assert not np.array_equal(a.telemetry.b_raw_nt, c.telemetry.b_raw_nt)


def test_world_measures_through_the_sensor(tle_text: str) -> None:
    w = _world(tle_text, 1, effects=[make_effect("external_field")])
    resid = w.sensor.invert(w.telemetry.b_raw_nt) - w.b_true_body_nt
    assert resid.std() < 3.0 * w.sensor.noise_std_nt
    np.testing.assert_allclose(
        w.b_true_body_nt - w.b_ref_body_nt, w.injected_body_nt["external_field"]
    )
    assert w.truth["verdict"] == "external_field"
    assert w.telemetry.r_itrs_km is None and w.telemetry.temperature_c is not None


def test_world_writes_a_directory(tmp_path: Path, tle_text: str) -> None:
    w = _world(tle_text, 2, effects=[make_effect("magnetorquer")], include_position=True)
    paths = w.write(tmp_path / "world", fmt="parquet")
    assert sorted(p.name for p in (tmp_path / "world").iterdir()) == [
        "spacecraft.tle",
        "telemetry.parquet",
        "truth.json",
        "truth_samples.parquet",
    ]
    res = read_telemetry(paths["telemetry"])
    assert res.rejected == [] and len(res.telemetry) == len(w.telemetry) == 180
    np.testing.assert_array_equal(res.telemetry.b_raw_nt, w.telemetry.b_raw_nt)
    truth = json.loads(paths["truth"].read_text())
    assert truth["spacecraft"] == "39452" and truth["reference_field"] == "IGRF-14"
    assert truth["effects"][0]["name"] == "magnetorquer" and truth["seed"] == 2
    assert np.array(truth["linear"]["M"]).shape == (3, 3)
    assert select_tle(paths["tle"].read_text()).line1 == w.tle.line1
    samples = pd.read_parquet(paths["truth_samples"])
    np.testing.assert_array_equal(
        samples["db_magnetorquer_x"], w.injected_body_nt["magnetorquer"][:, 0]
    )
    back = read_world(tmp_path / "world")
    assert back.truth == truth and back.tle_text == paths["tle"].read_text()
    np.testing.assert_array_equal(back.telemetry.mtq_am2, w.telemetry.mtq_am2)
    np.testing.assert_array_equal(back.samples["b_ref_z"], w.b_ref_body_nt[:, 2])


def test_frame_to_body_import_is_the_contract_convention() -> None:
    q = np.array([[np.cos(0.3), 0.0, 0.0, np.sin(0.3)]])
    v = np.array([[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(
        frame_to_body(v, q), Rotation.from_quat(q[:, [1, 2, 3, 0]]).inv().apply(v), atol=1e-15
    )


@pytest.mark.parametrize("name", sorted(CONTRACT_EFFECTS))
def test_scaled_effects_scale_their_disturbance(state: WorldState, name: str) -> None:
    base = make_effect(name)
    db1 = base.inject(state, np.random.default_rng(1)).db_body_nt
    db3 = base.scaled(3.0).inject(state, np.random.default_rng(1)).db_body_nt
    ratio = norm_rms_nt(db3) / norm_rms_nt(db1)
    # linear effects scale exactly; time_offset, orbit_error, attitude_error to first order
    assert ratio == pytest.approx(3.0, rel=0.01), name


def test_external_field_driven_by_the_rc_index(state: WorldState) -> None:
    db, _ = _inject(state, "external_field", model="RC")
    # NOTES: quiet-time external field ~10–20 nT at LEO
    assert 3.0 < norm_rms_nt(db) < 100.0


def test_orbit_error_true_tle_picks_its_spacecraft_from_a_file(
    state: WorldState, tle_text: str
) -> None:
    # the whole file: the Swarm A set nearest the start is the world's own one → zero error
    db, info = _inject(state, "orbit_error", true_tle=tle_text)
    assert abs(info["along_track_km_mean"]) < 1e-6 and np.abs(db).max() < 1e-6


def test_written_world_reproduces_its_reference_field_through_the_truth_pipeline(
    tmp_path: Path, tle_text: str
) -> None:
    """Simulator and truth pipeline agree: read the written telemetry and TLE back, recompute."""
    import warnings

    from orbitcal.orbit import Orbit
    from orbitcal.truth import truth_for_telemetry

    w = _world(tle_text, 3, attitude=Tumbling())
    back = read_world(w.write(tmp_path / "w", fmt="csv")["telemetry"].parent)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stale-elements warning: the TLE is days old
        truth = truth_for_telemetry(back.telemetry, orbit=Orbit.from_tle(back.tle_text))
    assert truth.b_body_nt is not None
    # CSV carries full-precision floats and µs times (exact at a 10 s cadence)
    np.testing.assert_allclose(truth.b_body_nt, w.b_ref_body_nt, rtol=0, atol=1e-6)


def test_sensor_change_in_orbit_wang2020_eq17(tle_text: str) -> None:
    from orbitcal.sensor import SensorModel

    ground, orbit = SensorModel.from_wang2020_ground(), SensorModel.wang2020_orbit_change()
    change = START_UTC_S + 900.0
    w = _world(tle_text, 8, sensor=ground, sensor_after=orbit, sensor_change_utc_s=change)
    after = w.telemetry.t_utc_s >= change
    assert 0.4 < after.mean() < 0.6
    res_before = ground.invert(w.telemetry.b_raw_nt[~after]) - w.b_true_body_nt[~after]
    res_after = orbit.invert(w.telemetry.b_raw_nt[after]) - w.b_true_body_nt[after]
    assert res_before.std() < 3.0 and res_after.std() < 3.0  # σ = 2 nT noise only
    # the ground calibration is wrong after the change by tens of nT
    stale = ground.invert(w.telemetry.b_raw_nt[after]) - w.b_true_body_nt[after]
    assert np.abs(stale).max() > 20.0
    assert w.truth["sensor_after"]["b0_nt"] == [-652.7, 1266.4, -444.49]


def test_solar_array_current_is_a_sunlight_witness(state: WorldState, tle_text: str) -> None:
    current = state.hk["hk_sa_current_a"]
    dark = state.illumination == 0.0
    assert np.abs(current[dark]).max() < 0.05  # noise only (σ = 0.01 A)
    # zenith-facing array of a nadir pointer: lit around the subsolar point, up to 2 A
    assert 1.5 < current[~dark].max() <= 2.05
    w = _world(tle_text, 1)
    x_hk, names = w.telemetry.regressors()
    assert names == ["temperature", "mtq_x", "mtq_y", "mtq_z", "hk_sa_current_a"]
    assert x_hk.shape == (len(w.telemetry), 5)


def test_real_swarm_storm_field_through_a_synthetic_sensor(
    authorities: Path, tmp_path: Path
) -> None:
    """Swarm A MAG_LR_1B, 2016-01-01 storm: measured B_NEC at its positions → raw telemetry."""
    import h5py

    from orbitcal.frames import spherical_to_itrs
    from orbitcal.simulate import simulate_measured_field

    with h5py.File(authorities / "test_fac_singlesat_swarm.nc4") as h:
        g = h["SW_OPER_MAGA_LR_1B"]
        t = pd.Timestamp("2016-01-01T00:00:00Z").timestamp() + g["Timestamp"][:].astype(float)
        r = spherical_to_itrs(g["Radius"][:] / 1e3, 90.0 - g["Latitude"][:], g["Longitude"][:])
        b_nec = g["B_NEC"][:]
    w = simulate_measured_field(
        t, r, b_nec, rng=np.random.default_rng(0), source="Swarm A MAG_LR_1B 2016-01-01"
    )
    assert w.tle is None and w.telemetry.r_itrs_km is not None
    gap = w.injected_body_nt["measured_minus_reference"]
    # storm (RC ≈ −129 nT) plus an auroral crossing: the gap to IGRF-14 is ~100 nT or more
    assert 50.0 < w.truth["effects"][0]["rms_nt"] < 1000.0
    # the measured magnitude survives the attitude rotation exactly
    np.testing.assert_allclose(
        np.linalg.norm(w.b_ref_body_nt + gap, axis=1), np.linalg.norm(b_nec, axis=1), rtol=1e-12
    )
    back = read_world(w.write(tmp_path / "swarm", fmt="parquet")["telemetry"].parent)
    assert back.tle_text == "" and len(back.telemetry) == 1800


def test_time_offset_under_tumbling_includes_the_body_rotation(tle_text: str) -> None:
    rate = (0.6, -1.2, 1.5)  # deg/s: ~2 °/s, so 0.1 s rotates B by ~0.2° (~140 nT)
    w = simulate_world(
        tle_text,
        norad_id=SWARM_A,
        start_utc_s=START_UTC_S,
        duration_s=600.0,
        cadence_s=0.5,
        rng=np.random.default_rng(0),
        attitude=Tumbling(rate_body_deg_s=rate),
        effects=[make_effect("time_offset", offset_s=0.1)],
    )
    assert w.truth["attitude"]["t0_utc_s"] == START_UTC_S
    db = w.injected_body_nt["time_offset"]
    rate_nt_s = np.gradient(w.b_ref_body_nt, w.telemetry.t_utc_s, axis=0)
    inner = slice(1, -1)  # central differences
    np.testing.assert_allclose(
        db[inner], -0.1 * rate_nt_s[inner], atol=0.03 * np.abs(0.1 * rate_nt_s).max()
    )
    assert norm_rms_nt(db) > 50.0


def test_world_options_and_keywords_simulate_the_same_world(tle_text: str) -> None:
    from orbitcal.simulate import WorldOptions

    options = WorldOptions(
        start_utc_s=START_UTC_S,
        duration_s=600.0,
        cadence_s=10.0,
        norad_id=SWARM_A,
        effects=[make_effect("temperature")],
        seed=4,
    )
    a = simulate_world(tle_text, rng=np.random.default_rng(4), options=options)
    b = simulate_world(
        tle_text,
        rng=np.random.default_rng(4),
        start_utc_s=START_UTC_S,
        duration_s=600.0,
        cadence_s=10.0,
        norad_id=SWARM_A,
        effects=[make_effect("temperature")],
        seed=4,
    )
    assert np.array_equal(a.telemetry.b_raw_nt, b.telemetry.b_raw_nt)
    assert a.truth == b.truth
    with pytest.raises(TypeError, match="options or keywords"):
        simulate_world(tle_text, rng=np.random.default_rng(4), options=options, seed=4)
