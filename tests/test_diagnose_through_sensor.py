"""Fields at the sensor are measured through the sensor's own matrix (issue 25, deliverable 6).

The joint fit writes every effect as a field added after the calibration, ``A b_ref + o + G c``.
A field outside the instrument (a time offset's shift of the main field, the ring current, a
torquer's stray field) reaches the output as ``A G c``: with ``A`` 1-2 % off identity its
parameters came out 1-2 % off, while their 90 % intervals were a fraction of that wide (the
independent generator's time offsets: 4 of 8 intervals held the truth). The stated parameters and
intervals now come from the model refitted with those templates seen through the fitted ``A``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.attribution.uncertainty import THROUGH_SENSOR, through_sensor
from orbitcal.diagnose.honesty import _fit_names

pytestmark = pytest.mark.usefixtures("single_thread_blas")  # tests/conftest.py


@pytest.mark.slow
def test_a_time_offset_through_a_sensor_matrix_off_identity_is_stated_within_its_interval() -> None:
    # Our simulator's sensor: A = I + N(0, 1 %); a 1 s time offset, tumbling. Seeds 0-3 are the
    # first four drawn (all four before the change: stated dt 0.2-1.8 % high).
    naive_err, shown_err = [], []
    for seed in range(4):
        w = make_world("time_offset", attitude="tumbling", seed=seed)
        att = diagnose_data(w.data).attribution
        assert att.verdict == "time_offset"
        effect = {e.name: e for e in att.effects}["time_offset"]
        lo, hi = effect.intervals["dt_s"]
        assert lo <= w.truth["dt_s"] <= hi, (seed, lo, hi)
        names = _fit_names(att)
        naive = float(att.fits["final"].coef[names.index("time_offset")][0])
        naive_err.append(abs(naive - w.truth["dt_s"]))
        shown_err.append(abs(float(effect.params["dt_s"]) - w.truth["dt_s"]))
    assert max(shown_err) < 0.003
    assert np.mean(shown_err) < 0.3 * np.mean(naive_err)


def test_effects_inside_the_instrument_are_not_refitted() -> None:
    w = make_world("temperature", seed=0)
    att = diagnose_data(w.data).attribution
    fit = att.fits["final"]
    assert "temperature" in att.selected
    assert not any(b.effect in THROUGH_SENSOR for b in fit.blocks)
    assert through_sensor(w.data, fit, att.train, robust=True) is fit
