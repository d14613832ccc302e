"""Imperfect-model columns (issue 43, item 2): an effect present in a form its template leaves out
is named alone by the model core, where without its group's imperfect-model columns the misfit
went to other effects (or the effect was not named at all)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.attribution.engine import training_split
from orbitcal.diagnose.columns import JoinedColumns
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.effects import CATALOGUE, block_ranges
from orbitcal.diagnose.imperfect import _lagged
from orbitcal.diagnose.model import model_diagnosis
from orbitcal.diagnose.model.report_keys import model_named
from orbitcal.diagnose.options import ModelOptions

FloatArray = np.ndarray


@contextmanager
def _without_imperfect_columns() -> Iterator[None]:
    """The catalogue with no effect's imperfect-model columns (the core as it was)."""
    saved = {e.name: e.imperfect for e in CATALOGUE}
    try:
        for e in CATALOGUE:
            object.__setattr__(e, "imperfect", None)
        yield
    finally:
        for e in CATALOGUE:
            object.__setattr__(e, "imperfect", saved[e.name])


def test_every_imperfect_column_has_a_shrinkage_prior() -> None:
    """Each imperfect-model column is finite and has a Gaussian prior centred on zero (its
    effect's ``param_ranges``), narrower than its range."""
    data = make_world("none", attitude="tumbling", seed=0).data
    train, _ = training_split(data)
    with_columns = [e for e in CATALOGUE if e.imperfect is not None]
    assert {e.name for e in with_columns} >= {
        "external_field",
        "temperature",
        "magnetorquer",
        "time_offset",
        "nonlinearity",
    }
    for eff in with_columns:
        assert eff.imperfect is not None
        block = eff.imperfect(data, train)
        assert block is not None, eff.name
        assert block.all_finite(), eff.name
        block = dataclasses.replace(block, effect=eff.name)
        for name, rng in zip(block.names, block_ranges(block), strict=True):
            assert rng.prior_sd is not None and rng.prior_mean == 0.0, (eff.name, name)
            assert 0.0 < rng.prior_sd < 0.5 * (rng.upper - rng.lower), (eff.name, name)


def test_lag_is_the_first_order_response_of_a_held_input() -> None:
    t = np.arange(0.0, 200.0, 2.0)
    u = np.where(t >= 50.0, 3.0, 0.0)
    tau = 10.0
    y = _lagged(t, u, tau)
    # the input is held from each sample to the next: the step is seen from the sample after
    on = t >= 50.0 + 2.0
    expected = np.where(on, 3.0 * (1.0 - np.exp(-(t - 50.0) / tau)), 0.0)
    np.testing.assert_allclose(y, expected, atol=1e-12)
    # a gap starts a new run at rest
    t2 = np.r_[t, t[-1] + 1000.0 + t]
    y2 = _lagged(t2, np.r_[u, u + 7.0], tau)
    assert y2[t.size] == 7.0
    # at rest at its first value: a run that starts (and stays) at 7 is 7 throughout (the
    # lfilter form of 2026-11-28 gave 7 (1 - a + a^2) at the run's second sample)
    np.testing.assert_allclose(y2[t.size : t.size + 25], 7.0, rtol=0, atol=1e-12)


def test_sm_axes_are_orthonormal_and_across_the_dipole() -> None:
    data = make_world("none", attitude="tumbling", seed=0).data
    sm = data.sm_equatorial_body
    assert sm is not None
    z = data.dipole_axis_body
    for v in (sm[:, 0], sm[:, 1]):
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.sum(v * z, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(sm[:, 0] * sm[:, 1], axis=1), 0.0, atol=1e-12)
    # x toward the Sun: its projection on the dipole equator
    assert np.all(np.sum(sm[:, 0] * data.sun_body, axis=1) >= 0.0)


def test_joined_columns_are_the_parts_side_by_side() -> None:
    a = np.arange(24.0).reshape(4, 3, 2)
    b = -np.arange(12.0).reshape(4, 3, 1)
    joined = JoinedColumns(4, [lambda i: a[i], lambda i: b[i]], [2, 1])
    assert joined.width == 3
    np.testing.assert_array_equal(joined(np.array([1, 3])), np.concatenate([a, b], 2)[[1, 3]])


def _departed(kind: str, data: DiagnosisData) -> FloatArray:
    """A field of the effect ``kind`` in a form its catalogue template leaves out [nT]."""
    if kind == "magnetorquer":  # the coils' field lags the commands by 30 s
        mtq = data.x_hk[:, 1:4]
        coupling = np.array([[4.0, -1.0, 0.5], [1.0, 3.0, -2.0], [0.0, 1.5, 5.0]])
        lag = np.column_stack([_lagged(data.t_utc_s, mtq[:, k], 30.0) for k in range(3)])
        return np.asarray((lag - mtq) @ coupling.T)
    if kind == "time_offset":  # a time-tag error of 0.8 s drifting by 0.6 s over the span
        tau = data.t_utc_s - data.t_utc_s.mean()
        dt_s = 0.8 + 0.3 * tau / tau.max()
        return np.asarray(data.db_ref_body_dt_nt_s * dt_s[:, None])
    if kind == "external_field":  # a ring current deeper on the dusk side
        assert data.mlt_angle_rad is not None
        asy = 40.0 * np.cos(data.mlt_angle_rad - np.radians(105.0))
        return np.asarray(data.dipole_axis_body * asy[:, None])
    if kind == "nonlinearity":  # cross-axis quadratic terms
        b = data.b_ref_body_nt / 5e4
        return np.column_stack(
            [20 * b[:, 0] * b[:, 1], -15 * b[:, 1] * b[:, 2], 25 * b[:, 0] * b[:, 2]]
        )
    if kind == "temperature":  # the sensor lags the thermistor by 10 min
        temp = data.x_hk[:, 0]
        lagged = _lagged(data.t_utc_s, temp, 600.0)
        return np.outer(lagged - temp, np.array([1.5, -1.0, 2.0]))
    raise ValueError(kind)


@pytest.mark.parametrize(
    "kind", ["magnetorquer", "time_offset", "external_field", "nonlinearity", "temperature"]
)
def test_an_effect_in_a_form_its_template_leaves_out_is_named_alone(kind: str) -> None:
    """Worlds of the test simulator (four orbits at 10 s, tumbling): the effect's own template
    where the simulator has one, plus its departure; the model core names it and nothing else.
    Without the imperfect-model columns the same world is not named so (the contrast shows the
    columns are what names it)."""
    world = make_world(kind if kind != "time_offset" else "none", attitude="tumbling", seed=1)
    data = dataclasses.replace(
        world.data, b_raw_nt=world.data.b_raw_nt + _departed(kind, world.data)
    )
    train, holdout = training_split(data)
    md = model_diagnosis(data, train, holdout)
    assert model_named(md, ModelOptions()) == (kind,), md.inclusion()
    assert all(p < 0.5 for e, p in md.inclusion().items() if e != kind), md.inclusion()
    with _without_imperfect_columns():
        before = model_diagnosis(data, train, holdout)
    assert model_named(before, ModelOptions()) != (kind,), before.inclusion()
