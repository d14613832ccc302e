"""The shrink's moving-block bootstrap interval on the model core's final block (issue 43,
item 4): its coverage on a persistent error of known size, its refusal on a block too short
for orbit-long blocks, and its place in the report."""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.model.confirm import (
    SHRINK_MIN_BLOCKS,
    Confirmation,
    confirm,
    shrink_interval,
)
from orbitcal.diagnose.model.noise_model import AxisNoise

WHITE = (AxisNoise("ar", np.zeros(0), 1.0, float("nan")),) * 3


def _ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """Unit-variance AR(1) series, (n, 3)."""
    x = np.empty((n, 3))
    x[0] = rng.normal(size=3)
    e = rng.normal(size=(n, 3)) * np.sqrt(1.0 - phi**2)
    for t in range(1, n):
        x[t] = phi * x[t - 1] + e[t]
    return x


def test_interval_covers_the_shrink_of_a_persistent_error_about_as_often_as_stated() -> None:
    """The calibration's error persists (AR(1), a correlation time of 50 samples, blocks of
    200); the model's is white. Over 200 final blocks of 20 blocks each, the 90 % interval holds
    the population shrink (3 nT / 1 nT) in 80-97 % of them."""
    rng = np.random.default_rng(20261129)
    covered = 0
    for _ in range(200):
        e_base = 3.0 * _ar1(rng, 4000, np.exp(-1.0 / 50.0))
        e_model = rng.normal(size=(4000, 3))
        lo, hi = shrink_interval(e_base, e_model, 200)  # type: ignore[misc]
        covered += lo <= 3.0 <= hi
    assert 0.80 <= covered / 200 <= 0.97, covered


def test_interval_is_reproducible_and_brackets_the_block_shrink() -> None:
    rng = np.random.default_rng(3)
    e_base = 5.0 * _ar1(rng, 3000, 0.99)
    e_model = rng.normal(size=(3000, 3))
    one = shrink_interval(e_base, e_model, 300)
    assert one == shrink_interval(e_base, e_model, 300)
    assert one is not None
    shrink = float(np.sqrt(np.mean(e_base**2) / np.mean(e_model**2)))
    assert one[0] < shrink < one[1]


@pytest.mark.parametrize("orbits", [0.5, 1.0, SHRINK_MIN_BLOCKS - 0.01])
def test_no_interval_on_a_block_shorter_than_the_least_number_of_orbits(orbits: float) -> None:
    rng = np.random.default_rng(5)
    m = int(orbits * 500)
    e_base, e_model = 3.0 * rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    assert shrink_interval(e_base, e_model, 500) is None
    c = confirm(e_base, e_model, WHITE, np.array([0]), block_samples=500)
    assert c.shrink_interval is None and c.bootstrap_block_samples == 0
    assert c.to_json()["shrink_interval_90"] is None
    assert c.to_json()["shrink"] == pytest.approx(
        c.holdout_rms_before_nt / c.holdout_rms_after_nt, rel=1e-3
    )


def test_confirmation_json_carries_the_shrink_and_its_interval() -> None:
    rng = np.random.default_rng(8)
    e_base, e_model = 4.0 * rng.normal(size=(2000, 3)), rng.normal(size=(2000, 3))
    c = confirm(e_base, e_model, WHITE, np.array([0]), block_samples=400)
    out = c.to_json()
    lo, hi = out["shrink_interval_90"]  # type: ignore[misc]
    assert lo < out["shrink"] < hi and out["bootstrap_block_samples"] == 400
    assert Confirmation(2.0, 0.0, 0.0, 1e9, 10).to_json()["shrink"] is None  # a perfect forecast


def test_model_core_reports_the_interval_over_orbit_long_blocks() -> None:
    """Our simulator's temperature world over ten orbits: the final block holds more than two
    orbits, and the confirmation has an interval over blocks of one orbit's samples; over four
    orbits it holds less than two, and has none."""
    from orbitcal.diagnose.attribution.engine import training_split
    from orbitcal.diagnose.model import model_diagnosis
    from orbitcal.diagnose.model.crossval import orbital_period_s

    for n_orbits, has_interval in ((10.0, True), (4.0, False)):
        world = make_world("temperature", attitude="tumbling", seed=3, n_orbits=n_orbits)
        train, holdout = training_split(world.data)
        md = model_diagnosis(world.data, train, holdout)
        c = md.confirmation
        orbit = int(np.ceil(orbital_period_s(world.data) / 10.0))
        assert bool(holdout.sum() >= SHRINK_MIN_BLOCKS * orbit) is has_interval
        assert md.chosen == ("temperature",)
        if has_interval:
            assert c.bootstrap_block_samples == orbit and c.shrink_interval is not None
            assert 1.0 < c.shrink_interval[0] <= c.shrink < c.shrink_interval[1]
        else:
            assert c.shrink_interval is None and c.bootstrap_block_samples == 0
