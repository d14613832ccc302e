"""The catalogue owns its parameters' ranges: every parameter of every effect's design (each
alternative form and a refinement of it) gets a finite range from its own effect, and the joint
fit reads them from the block's effect, never by a global table of names."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.attribution import time_blocks
from orbitcal.diagnose.bounds import FREE
from orbitcal.diagnose.effects import (
    CATALOGUE,
    DesignBlock,
    block_inconsistencies,
    block_ranges,
    effect_param_range,
    get_effect,
)


def _forms(block: DesignBlock) -> Iterator[DesignBlock]:
    yield block
    for alt in block.alternatives:
        yield alt
        if alt.refine is not None:
            yield from alt.refine()


@pytest.mark.parametrize("name", [e.name for e in CATALOGUE])
def test_every_parameter_has_its_effects_range(name: str) -> None:
    data = make_world(name, attitude="tumbling", seed=3).data
    train, _, _ = time_blocks(data.t_utc_s)
    effect = get_effect(name)
    block = effect.design(data, train)
    assert block is not None
    for form in _forms(block):
        assert form.effect == name
        for param, rng in zip(form.names, block_ranges(form), strict=True):
            assert np.isfinite(rng.lower) and np.isfinite(rng.upper), (name, param)
            assert rng.lower < rng.upper
            assert rng == effect.param_range(param) == effect_param_range(name, param)


def test_a_block_of_no_effect_is_free_and_unchecked() -> None:
    block = DesignBlock(np.zeros((4, 3, 2)), ["dt_s", "dt_squared_s2"])
    assert block_ranges(block) == [FREE, FREE]
    assert block_inconsistencies(block, [1.0, 20.0], [0.01, 0.01]) == []
    owned = DesignBlock(block.source, block.names, effect="time_offset")
    assert block_ranges(owned)[0].upper == 5.0
    assert block_inconsistencies(owned, [1.0, 20.0], [0.01, 0.01])
    assert effect_param_range("not_an_effect", "dt_s") == FREE
