"""The independent world generator (``benchmarks/independent/``, issue 43 item 8) draws what it
says: all eleven effects, one to three at once, the shapes the catalogue does not write (a scale
factor moved by the temperature, a torquer field lagging its command, a ring current with a
local-time asymmetry, Sq and the electrojet, star-tracker steps), coloured noise different per
axis, spans of 2-24 h and cadences of 1-30 s; and records the truth of each world."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from contract_doc import CONTRACT_EFFECTS

HERE = Path(__file__).resolve().parents[1] / "benchmarks" / "independent"
sys.path.insert(0, str(HERE))

import noise  # noqa: E402
import shapes  # noqa: E402
import world  # noqa: E402


def test_the_generator_knows_the_eleven_effects_and_draws_one_to_three() -> None:
    assert set(world.EFFECTS) == CONTRACT_EFFECTS
    drawn = [world.draw_effects(np.random.default_rng(s)) for s in range(300)]
    assert {len(d) for d in drawn} == {1, 2, 3}
    assert {e for d in drawn for e in d} == CONTRACT_EFFECTS
    assert all(len(set(d)) == len(d) for d in drawn)


def test_spans_and_cadences_are_drawn_within_2_to_24_h_and_1_to_30_s() -> None:
    draws = [world.draw_span_and_cadence(np.random.default_rng(s)) for s in range(400)]
    spans = np.array([d[0] for d in draws])
    cadences = np.array([d[1] for d in draws])
    assert spans.min() >= 2.0 and spans.max() <= 24.0
    assert spans.min() < 3.0 and spans.max() > 18.0  # the whole range is reached
    assert set(cadences) == set(world.CADENCES_S)
    assert cadences.min() == 1.0 and cadences.max() == 30.0


def test_the_torquer_field_lags_its_command_by_the_drawn_lag() -> None:
    t = np.arange(0.0, 300.0, 0.05)
    control_t = np.array([-10.0, 100.0])
    control_u = np.array([[0.0, 0.0, 0.0], [4.0, -2.0, 1.0]])  # a step of the command at 100 s
    field_nt, truth = shapes.lagged_torquer(np.random.default_rng(3), t, control_t, control_u)
    lag_s = truth["lag_s"]
    assert 1.0 <= lag_s <= 15.0
    final = field_nt[-1]
    at = int(np.searchsorted(t, 100.0 + lag_s))
    # a first-order lag reaches 1 - 1/e of the step after one time constant, on every axis
    np.testing.assert_allclose(field_nt[at] / final, 1.0 - np.exp(-1.0), atol=0.01)
    assert np.all(np.abs(field_nt[t < 100.0]) < 1e-12)  # nothing before the command
    # a field in step with the command (no lag) would be at its final value at once
    assert np.all(np.abs(field_nt[np.searchsorted(t, 100.2)] / final) < 0.2)
    # the same at a 10 s cadence: the lag is evaluated at the samples, not on their grid
    coarse = np.arange(0.0, 300.0, 10.0)
    field_10s, _ = shapes.lagged_torquer(np.random.default_rng(3), coarse, control_t, control_u)
    np.testing.assert_allclose(field_10s, field_nt[np.searchsorted(t, coarse)], atol=1e-9)


def test_the_table_gives_the_command_active_at_each_sample() -> None:
    t = np.arange(0.0, 600.0, 7.0)
    b = np.column_stack([np.sin(t / 50.0), np.cos(t / 70.0), np.sin(t / 90.0)]) * 1e4
    cmd, control_t, control_u, truth = shapes.torquer_commands(np.random.default_rng(1), t, b)
    assert 4.0 <= truth["control_period_s"] <= 30.0
    for k in (0, 10, 50, len(t) - 1):
        j = np.searchsorted(control_t, t[k], side="right") - 1
        np.testing.assert_array_equal(cmd[k], control_u[j])


def test_first_order_lag_is_exact_for_a_held_command() -> None:
    t = np.array([0.0, 1.0, 3.0, 4.0])
    y = shapes.first_order_lag(np.array([1.0, 1.0, 1.0, 1.0]), t, 2.0, np.asarray(0.0))
    np.testing.assert_allclose(y, 1.0 - np.exp(-t / 2.0))


def test_magnetic_local_time_is_noon_towards_the_sun_and_dusk_eastward() -> None:
    north = np.array([0.0, 0.0, 1.0])
    sun = np.tile([1.0, 0.0, 0.0], (4, 1))
    r = np.array([[7000.0, 0, 0], [0, 7000.0, 0], [-7000.0, 0, 0], [0, -7000.0, 0]])
    mlt = shapes.magnetic_local_time_h(r, north, sun)
    np.testing.assert_allclose(mlt, [12.0, 18.0, 0.0, 6.0], atol=1e-9)


def test_the_ring_current_is_deeper_at_dusk_than_at_dawn() -> None:
    t = np.arange(0.0, 12 * 3600.0, 60.0)
    dusk = shapes.partial_ring_current(np.random.default_rng(5), t, np.full(t.size, 18.0))
    dawn = shapes.partial_ring_current(np.random.default_rng(5), t, np.full(t.size, 6.0))
    (size_dusk, truth), (size_dawn, _) = dusk, dawn
    assert np.all(size_dusk <= 0.0) and size_dusk.min() < -20.0  # a depression
    asymmetry = size_dawn - size_dusk  # 2 ASY cos(...) >= 0 for a dusk between 16 and 20 h
    assert asymmetry.max() > 0.3 * truth["sym_peak_nt"]
    assert np.all(asymmetry >= -1e-9)
    # uniform (the catalogue's and our simulator's ring current) would make them equal
    assert not np.allclose(size_dusk, size_dawn)


def test_the_temperature_moves_the_scale_factor_as_well_as_the_offset() -> None:
    t = np.arange(0.0, 4 * 5650.0, 10.0)
    sunlit = (np.sin(2 * np.pi * t / 5650.0) > -0.3).astype(float)
    sun_body = np.tile([0.6, 0.0, 0.8], (t.size, 1))
    b = np.column_stack([2e4 + 0 * t, -1e4 + 0 * t, 3e4 + 0 * t])
    one = shapes.thermal_sensor(np.random.default_rng(2), t, sunlit, sun_body, b)
    two = shapes.thermal_sensor(np.random.default_rng(2), t, sunlit, sun_body, 2 * b)
    (added_1, thermistor, truth), (added_2, _, _) = one, two
    assert truth["temperature_span_c"] > 3.0
    scale_part = added_2 - added_1  # what grows with the field: b x ppm x dT
    assert np.abs(scale_part).max() > 0.2  # nT
    dtemp = np.corrcoef(scale_part[:, 0], added_1[:, 0] - scale_part[:, 0])
    assert np.isfinite(dtemp).all()
    offset_part = added_1 - scale_part
    assert np.abs(offset_part).max() > 1.0  # the offset moves too
    # the thermistor lags the sensor: it is quantised to 0.1 degC and not the sensor's copy
    assert np.allclose(thermistor, np.round(thermistor, 1))


def test_sq_and_the_electrojet_are_dayside_and_peak_at_the_dip_equator() -> None:
    lat = np.linspace(-60.0, 60.0, 241)
    r_noon = world.spherical_to_itrs_km(np.full(lat.size, 6821.0), lat, np.zeros(lat.size))
    sun = np.tile([1.0, 0.0, 0.0], (lat.size, 1))
    basis = world.nec_basis(r_noon)
    noon, truth = shapes.sq_and_electrojet(np.random.default_rng(4), r_noon, sun, lat, basis)
    night, _ = shapes.sq_and_electrojet(np.random.default_rng(4), r_noon, -sun, lat, basis)
    assert np.abs(night).max() < 1e-9  # nothing on the night side
    nec = np.einsum("nki,ni->nk", basis, noon)
    eej_region = np.abs(lat) < 5
    assert np.abs(nec[:, 0]).max() > 5.0
    # the electrojet's north component at the satellite is largest over the dip equator
    assert np.argmax(np.abs(nec[:, 0])) in np.flatnonzero(eej_region)
    assert truth["electrojet_ka"] >= 30.0


def test_the_attitude_error_steps_when_the_star_tracker_head_changes() -> None:
    t = np.arange(0.0, 6 * 5650.0, 5.0)
    rv, truth = shapes.star_tracker_steps(np.random.default_rng(8), t, 5650.0)
    assert truth["switches"] >= 6  # a head blinded once an orbit
    jumps = np.linalg.norm(np.diff(rv, axis=0), axis=1)
    small = np.median(jumps)
    big = np.sort(jumps)[-truth["switches"] :]
    assert big.min() > 5 * small
    assert np.degrees(big.max()) < 3 * truth["step_deg"]


@pytest.mark.parametrize("kind", noise.NOISE_KINDS)
def test_every_noise_kind_is_drawn_at_about_its_level(kind: str) -> None:
    t = np.arange(0.0, 20000.0, 5.0)
    x, drawn = noise.sensor_noise(np.random.default_rng(11), t, kind, 2.0)
    assert x.shape == (t.size, 3) and drawn["kind"] == kind
    assert len(drawn["axis_kinds"]) == 3 and set(drawn["axis_kinds"]) <= set(noise.COLOURED)
    for k in range(3):
        assert 0.3 * drawn["axis_sigma_nt"][k] < x[:, k].std() < 2.5 * drawn["axis_sigma_nt"][k]


def test_per_axis_noise_differs_from_axis_to_axis() -> None:
    t = np.arange(0.0, 20000.0, 5.0)
    draws = [noise.sensor_noise(np.random.default_rng(s), t, "per_axis", 2.0) for s in range(12)]
    assert any(len(set(d["axis_kinds"])) > 1 for _, d in draws)
    assert all(len(set(np.round(d["axis_sigma_nt"], 9))) > 1 for _, d in draws)
    # a coloured axis is correlated from sample to sample, a white one is not
    for x, d in draws:
        for k, kind in enumerate(d["axis_kinds"]):
            lag1 = np.corrcoef(x[:-1, k], x[1:, k])[0, 1]
            assert (lag1 > 0.3) if kind != "white" else (abs(lag1) < 0.1), (kind, lag1)


def test_a_whole_world_with_the_eleven_effects_records_its_truth() -> None:
    effects = sorted(CONTRACT_EFFECTS)
    args = dict(noise="per_axis", span_h=2.0, cadence_s=30.0)
    full = world.make_world(np.random.default_rng(7), effects, **args)  # type: ignore[arg-type]
    bare = world.make_world(
        np.random.default_rng(7),
        effects,
        exclude=frozenset(effects),
        **args,  # type: ignore[arg-type]
    )
    assert set(full.truth["effects"]) == CONTRACT_EFFECTS
    assert all(isinstance(v, dict) and v for v in full.truth["effects"].values())
    assert full.truth["span_h"] == 2.0 and full.truth["cadence_s"] == 30.0
    assert full.t_unix_s.size == 240 and np.all(np.diff(full.t_unix_s) == 30.0)
    assert np.isfinite(full.b_raw_nt).all()
    assert {"temperature", "mtq_x", "mtq_y", "mtq_z"} <= set(full.extra)
    assert "dt_s" in full.truth and full.truth["noise"]["kind"] == "per_axis"
    # the same draws without the effects applied: same times, attitude and columns, other data
    np.testing.assert_array_equal(bare.t_unix_s, full.t_unix_s)
    np.testing.assert_array_equal(bare.extra["temperature"], full.extra["temperature"])
    assert np.abs(full.b_raw_nt - bare.b_raw_nt).max() > 50.0
    with pytest.raises(ValueError, match="unknown effects"):
        world.make_world(np.random.default_rng(7), ["ring_current"])
