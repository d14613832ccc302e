"""An attitude error that wanders: a random walk beside a twice-per-orbit flex.

The independent generator's attitude error (``benchmarks/independent/world.py``) is a thermal
flex at twice the orbital frequency plus a random walk. Sinusoids alone followed the walk on the
training blocks with periods as long as the span (16,000-20,000 s) and continued it at random
into the held-out blocks after the span: the diagnosis named nothing, or the temperature. The
attitude error's design now has a drift held at its last value after the training span, periods
of at least two cycles on it, and the fewest periods that predict the end of the training span.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from orbitcal.data import real_tles_text
from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.attitude_scan import ATTITUDE_MAX_PERIOD_FRACTION, design_attitude
from orbitcal.diagnose.attribution import fit_joint, time_blocks
from orbitcal.diagnose.bench import BENCH_OPTIONS, CompoundCase, simulate_compound_world

ORBIT_S = 5650.0


def _wandering_world(seed: int):
    """A nadir world with no effect, then an attitude error of 0.08 deg: flex at twice the
    orbital frequency plus a random walk of half that at most (the generator's shapes)."""
    case = CompoundCase(
        index=0, effects=(), magnitudes=(), attitude="nadir", norad_id=39452, seed=seed
    )
    _, data = simulate_compound_world(case, tle_text=real_tles_text())
    t = data.t_utc_s - data.t_utc_s[0]
    rng = np.random.default_rng(seed)
    amp_rad = np.radians(0.08)
    flex = amp_rad * np.sin(4 * np.pi * t / ORBIT_S + 1.0)
    walk = np.cumsum(rng.normal(size=(t.size, 3)), axis=0)
    walk = 0.5 * amp_rad * walk / np.abs(walk).max()
    rotvec = walk + np.outer(flex, [0.6, -0.5, 0.62])
    db_nt = -np.cross(rotvec, data.b_ref_body_nt)
    return dataclasses.replace(data, b_raw_nt=data.b_raw_nt + db_nt)


@pytest.mark.parametrize("seed", [2, 3])
def test_a_wandering_attitude_error_is_named(seed):
    """At a77c877 (sinusoids only) the verdicts were "temperature" (seed 2) and "none" (seed 3)."""
    data = _wandering_world(seed)
    train, holdout, _ = time_blocks(data.t_utc_s)
    block = design_attitude(data, train)
    assert block is not None
    span_s = float(data.t_utc_s[train][-1] - data.t_utc_s[train][0])
    periods = [float(p) for p in block.variant.split("=")[1].split(" and")[0].split(",")]
    assert all(p < ATTITUDE_MAX_PERIOD_FRACTION * span_s for p in periods), periods
    # the drift (the last three columns) is held at its last value after the training span
    drift = block.rows(np.flatnonzero(holdout)).reshape(-1, 3, block.width)[:, :, -3:]
    last = block.rows(np.flatnonzero(train)[-1:]).reshape(-1, 3, block.width)[:, :, -3:]
    b_hold = data.b_ref_body_nt[holdout]
    rot = np.stack([np.cross(np.eye(3)[k], b_hold) for k in range(3)], axis=2) * 1e-3
    np.testing.assert_allclose(drift, rot, atol=1e-12)
    assert np.abs(last).max() > 0.0
    base = fit_joint(data, train)
    fit = fit_joint(data, train, [block])

    def holdout_rms_nt(f) -> float:
        return float(np.sqrt(np.mean((data.b_raw_nt - f.predict_nt(data))[holdout] ** 2)))

    assert holdout_rms_nt(fit) < 0.75 * holdout_rms_nt(base)
    report = diagnose_data(data, options=BENCH_OPTIONS).report.to_json()
    assert report["verdict"] == "attitude_error", report["verdict"]
    named = [e["name"] for e in report["effects"] if e.get("significant")]
    assert named == ["attitude_error"], named


def _stepping_world(seed: int, *, offset_step_nt: float = 0.0):
    """The wandering world with a rotation step of 0.04 deg at 55 % of the span (a jump of the
    walk) and, if asked, a real step of the x offset at the same time."""
    from orbitcal.diagnose.effects import get_effect

    data = _wandering_world(seed)
    t = data.t_utc_s - data.t_utc_s[0]
    rng = np.random.default_rng(100 + seed)
    after = (t > 0.55 * t[-1]).astype(float)
    jump = np.radians(0.04) * rng.normal(size=3) / np.sqrt(3.0)
    raw = data.b_raw_nt - np.cross(np.outer(after, jump), data.b_ref_body_nt)
    raw[:, 0] += offset_step_nt * after
    data = dataclasses.replace(data, b_raw_nt=raw)
    train, holdout, _ = time_blocks(data.t_utc_s)
    attitude = get_effect("attitude_error").design(data, train)
    drift = get_effect("parameter_drift").design(data, train)
    assert attitude is not None and drift is not None
    t_step = data.t_utc_s[0] + 0.55 * t[-1]
    steps = [b for b in drift.alternatives if b.variant.startswith("step@")]
    step = min(steps, key=lambda b: abs(float(b.variant[5:].split("+")[0]) - t_step))
    return data, train, holdout, fit_joint(data, train, [attitude, step])


def test_a_drift_that_takes_up_the_walk_of_an_attitude_error_is_a_residue(monkeypatch) -> None:
    """A drift of the parameters stepping where the attitude error's walk jumps takes up part of
    the jump (bias and scale steps projected on a rotation): without a wandering rotation in the
    attitude error's imperfect model it explained the held-out blocks beyond a residue (18.8 ->
    13.6 nT, p = 0.0013); with it, it does not. Independent worlds 13200 no. 5 and 11, 13700 no. 12
    and 14, 13800 no. 19 named such a drift beside an attitude error."""
    from orbitcal.diagnose import residue

    data, train, holdout, fit = _stepping_world(4)
    assert residue.residue_test(data, fit, 1, train, holdout).residue
    monkeypatch.setattr(residue, "rotation_wander", lambda data, variant: [])
    assert not residue.residue_test(data, fit, 1, train, holdout).residue


def test_a_real_offset_step_beside_a_wandering_attitude_error_is_no_residue() -> None:
    from orbitcal.diagnose import residue

    data, train, holdout, fit = _stepping_world(4, offset_step_nt=25.0)
    assert not residue.residue_test(data, fit, 1, train, holdout).residue
