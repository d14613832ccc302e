"""The magnetorquer effect from torquer *currents* (GRACE-FO's MAG1B ``torque1A`` ... ``torque3B``,
ingested as ``hk_torque1a_ma`` ...) when the table has no dipole commands ``mtq_*``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose import attribute
from orbitcal.diagnose.design import torquer_currents
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.diagnose.options import AttributionOptions

CHANNELS = ("hk_torque1a_ma", "hk_torque1b_ma", "hk_torque2a_ma", "hk_torque2b_ma")


def _with_currents(
    data: DiagnosisData, coupling_nt_per_ma: np.ndarray, seed: int
) -> tuple[DiagnosisData, np.ndarray]:
    """``data`` with four current channels (one idle, one a copy of another at twice its
    current) and a battery voltage, their field added to the raw measurement."""
    rng = np.random.default_rng(seed)
    n = data.n
    steps = rng.normal(0.0, 40.0, (n // 6 + 1, 2))  # mA, switching every 6 samples
    on = np.repeat(steps, 6, axis=0)[:n]
    currents_ma = np.column_stack([on[:, 0], np.zeros(n), on[:, 1], 2.0 * on[:, 0]])
    battery_v = 28.0 + rng.normal(0.0, 0.3, n)
    field_nt = on @ coupling_nt_per_ma.T
    out = dataclasses.replace(
        data,
        b_raw_nt=data.b_raw_nt + field_nt,
        x_hk=np.column_stack([currents_ma, battery_v]),
        hk_names=(*CHANNELS, "hk_battery_v"),
    )
    return out, currents_ma


def test_torquer_channels_are_the_varying_distinct_current_columns() -> None:
    data, currents_ma = _with_currents(
        make_world("none", seed=5, n_orbits=2.0).data, np.zeros((3, 2)), seed=1
    )
    found = torquer_currents(data)
    # the idle coil, the redundant copy and the battery voltage are left out
    assert [name for name, _ in found] == ["hk_torque1a_ma", "hk_torque2a_ma"]
    np.testing.assert_allclose(found[0][1], currents_ma[:, 0] * 1e-3)  # milliamperes -> A


def test_a_channel_in_amperes_is_read_as_such() -> None:
    data = make_world("none", seed=5, n_orbits=2.0).data
    x = np.random.default_rng(2).normal(0.0, 0.05, data.n)
    data = dataclasses.replace(data, x_hk=x[:, None], hk_names=("hk_mtq_coil_x_a",))
    ((name, amps),) = torquer_currents(data)
    assert name == "hk_mtq_coil_x_a"
    np.testing.assert_allclose(amps, x)


@pytest.mark.parametrize("attitude", ["nadir", "tumbling"])
def test_torquer_currents_are_named_and_their_coupling_recovered(attitude: str) -> None:
    k_nt_per_ma = np.array([[0.4, -0.2], [-0.3, 0.5], [0.25, 0.35]])
    data, _ = _with_currents(make_world("none", attitude=attitude, seed=7).data, k_nt_per_ma, 3)
    att = attribute(data, options=AttributionOptions(split_tests=False))
    assert att.verdict == "magnetorquer", [(e.name, e.holdout_rms_after_nt) for e in att.effects]
    top = att.effects[0]
    assert top.params["variant"] == "currents"
    # the noise floor is 2 nT per axis: 3.46 nT as a vector
    assert att.final_rms_nt < 1.2 * 2.0 * np.sqrt(3.0)
    for i, axis in enumerate("xyz"):
        for j, ch in enumerate(("torque1a_ma", "torque2a_ma")):
            value = top.params[f"current_coupling_{axis}_{ch}_nt_per_a"]
            assert value == pytest.approx(1e3 * k_nt_per_ma[i, j], abs=15.0), (axis, ch)


def test_currents_without_a_coupling_raise_no_false_alarm() -> None:
    data, _ = _with_currents(make_world("none", seed=9).data, np.zeros((3, 2)), seed=4)
    att = attribute(data, options=AttributionOptions(split_tests=False))
    assert att.verdict == "none", [(e.name, e.p_value) for e in att.effects[:3]]
