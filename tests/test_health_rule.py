"""The calibration-health change rule (orbitcal.health): no alarm on stationary series at the
stated rate, a step caught within the stated delay, the change point where the step began."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orbitcal.health import (
    ChangeRule,
    cusum,
    false_alarm_rate,
    first_alarm,
    variance_change_index,
)

RULE = ChangeRule()


def _alarms(x: np.ndarray, rule: ChangeRule) -> int:
    """Alarms of the CUSUM over log ratios ``x``, restarted after each alarm."""
    n, s = 0, 0.0
    for xi in x:
        s = max(0.0, s + float(xi) - rule.kappa)
        if s >= rule.h:
            n, s = n + 1, 0.0
    return n


def test_no_alarm_on_a_stationary_series_of_many_uploads() -> None:
    rng = np.random.default_rng(47)
    # 10^5 uploads whose RMS wanders ±25 % (log spread 0.25, 12x that of 1,000 white samples)
    rms = 2.0 * np.exp(rng.normal(0.0, 0.25, 100_000))
    assert first_alarm(rms, 2.0) is None
    assert false_alarm_rate(0.25) < 1e-12


def test_false_alarm_rate_of_a_wide_series_is_the_stated_order() -> None:
    rng = np.random.default_rng(3)
    n = 200_000
    measured = _alarms(rng.normal(0.0, 0.5, n), RULE) / n
    stated = false_alarm_rate(0.5)
    # the stated rate counts the likeliest run length only: the measured one is above it, but
    # within a small factor
    assert stated <= measured <= 5 * stated


@pytest.mark.parametrize(("ratio", "delay"), [(125.0, 1), (10.0, 1), (4.5, 2), (3.0, 4)])
def test_a_step_is_caught_after_the_stated_delay(ratio: float, delay: int) -> None:
    rng = np.random.default_rng(int(ratio))
    before = 2.0 * np.exp(rng.normal(0.0, 0.02, 30))
    after = 2.0 * ratio * np.exp(rng.normal(0.0, 0.02, 10))
    alarm = first_alarm(np.concatenate([before, after]), 2.0)
    assert RULE.delay(ratio) == delay
    assert alarm is not None
    assert alarm.at == 30 + delay - 1
    assert alarm.run_start == 30  # the change began at the first point after it


def test_an_error_twice_the_held_out_one_is_never_flagged() -> None:
    assert RULE.delay(2.0) is None
    assert first_alarm(np.full(1000, 4.0), 2.0) is None
    assert cusum([4.0, 4.0], 2.0).tolist() == [0.0, 0.0]


def test_the_alarm_point_needs_the_whole_step_in_one_batch_only_partly() -> None:
    """The demo's case: the sensor changes inside an upload; 1 % of its samples at 125x the
    error already raise the batch RMS past 8x (one-batch detection)."""
    rng = np.random.default_rng(5)
    batch = rng.normal(0.0, 2.0, (360, 3))
    batch[-4:] += rng.normal(0.0, 250.0, (4, 3))
    rms = float(np.sqrt(np.mean(batch**2)))
    assert RULE.alarm(RULE.step(0.0, rms, 2.0))


@pytest.mark.parametrize("at", [1, 37, 180, 359])
def test_the_change_sample_is_the_variance_split(at: int) -> None:
    rng = np.random.default_rng(at)
    r = rng.normal(0.0, 2.0, (360, 3))
    r[at:] = rng.normal(0.0, 250.0, (360 - at, 3))
    assert variance_change_index(r) == at


def test_delay_formula() -> None:
    for ratio in (2.5, 3.0, 4.0, 10.0):
        expected = math.ceil(RULE.h / (math.log(ratio) - RULE.kappa))
        assert RULE.delay(ratio) == max(1, expected)
