"""The attitude-error period scan: beside effects already selected, and with collinear ones."""

from __future__ import annotations

import numpy as np
import pytest

from orbitcal.data import real_tles_text
from orbitcal.diagnose.attitude_scan import AttitudeScan, design_attitude
from orbitcal.diagnose.attribution import time_blocks
from orbitcal.diagnose.bench import plan_compound_cases, simulate_compound_world
from orbitcal.diagnose.effects import DesignBlock, get_effect

#: The simulator's attitude error: three sinusoids of 5,400 s x (1, 1.3, 0.7).
INJECTED_PERIODS_S = (3780.0, 5400.0, 7020.0)


@pytest.fixture(scope="module")
def attitude_and_time_offset():
    """A nadir world with an attitude error and a time-tag error, both at twice the default
    (compound benchmark seed 1, world 30: the scan on the calibration-only residual picked
    5,108 s for 5,400 s, and orbit_error stood in for the rest)."""
    case = plan_compound_cases(40, seed=1)[30]
    assert case.effects == ("attitude_error", "time_offset") and case.attitude == "nadir"
    _, data = simulate_compound_world(case, tle_text=real_tles_text())
    train, _, _ = time_blocks(data.t_utc_s)
    return data, train


def _periods(block: DesignBlock) -> list[float]:
    return sorted(float(p) for p in block.variant.split("=")[1].split(" and")[0].split(","))


def test_periods_found_beside_the_time_offset_are_the_injected_ones(attitude_and_time_offset):
    data, train = attitude_and_time_offset
    time_offset = get_effect("time_offset").design(data, train)
    assert time_offset is not None
    block = design_attitude(data, train, fixed=[time_offset])
    assert block is not None
    found = _periods(block)
    assert len(found) == 3
    np.testing.assert_allclose(found, INJECTED_PERIODS_S, rtol=0.01)


def test_scan_basis_stays_orthonormal_when_a_fixed_block_repeats_the_calibration(
    attitude_and_time_offset,
):
    """A fixed regressor equal to a calibration column (an offset on x) leaves R singular: the
    basis drops that direction instead of blowing up."""
    data, train = attitude_and_time_offset
    offset_x = np.zeros((data.n, 3, 1))
    offset_x[:, 0, 0] = 1.0
    scan = AttitudeScan(data, train, [DesignBlock(offset_x, ["offset_again_nt"])])
    basis = scan.basis([5400.0])
    q = np.vstack([scan.q_rows(basis, a0, a1) for a0, a1 in scan.blocks()])
    assert q.shape[1] == 12 + 6  # the repeated offset contributes no direction
    np.testing.assert_allclose(q.T @ q, np.eye(q.shape[1]), atol=1e-8)


@pytest.fixture(scope="module")
def attitude_time_offset_external():
    """A nadir world with a time-tag error (twice the default), a ring-current field and an
    attitude error (compound benchmark seed 51, world 17: nothing was named before the beam)."""
    case = plan_compound_cases(18, seed=51)[17]
    assert set(case.effects) == {"time_offset", "external_field", "attitude_error"}
    _, data = simulate_compound_world(case, tle_text=real_tles_text())
    train, _, _ = time_blocks(data.t_utc_s)
    return data, train


@pytest.mark.parametrize("beam", [1, 3])
def test_periods_found_beside_the_time_offset_and_the_ring_current(
    attitude_time_offset_external, monkeypatch, beam
):
    """Beside the time offset and the ring current, the greedy scan (a beam of one) took a first
    period from the mixture of the three sinusoids and ended at 6,576 / 4,238 / 9,189 s, twice the
    training residual of the injected periods; a beam of three sets found them. Since the
    attitude error has a drift (a linear trend of dtheta, in the scan's projection), the greedy
    scan finds them too; the beam stays for mixtures the drift does not take apart."""
    import orbitcal.diagnose.attitude_scan as attitude_scan

    data, train = attitude_time_offset_external
    fixed = [
        b
        for b in (get_effect(n).design(data, train) for n in ("time_offset", "external_field"))
        if b is not None
    ]
    monkeypatch.setattr(attitude_scan, "ATTITUDE_BEAM", beam)
    block = design_attitude(data, train, fixed=fixed)
    assert block is not None
    found = _periods(block)
    # 2 %: the drift takes a little of the slow part of the three sinusoids (5,484 s is found
    # for 5,400 s)
    np.testing.assert_allclose(found, INJECTED_PERIODS_S, rtol=0.02)
