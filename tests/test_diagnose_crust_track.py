"""The crustal model evaluated along the track every 10 s and interpolated, against every sample."""

from __future__ import annotations

from functools import partial

import numpy as np

from orbitcal.diagnose.prepare import CRUST_KNOT_SPACING_S, field_itrs_nt
from orbitcal.diagnose.track import along_track

crust = partial(field_itrs_nt, "LCS-1")


def _track(t_s: np.ndarray) -> np.ndarray:
    """A polar circular orbit 450 km up (ITRS km), one revolution in 5,600 s."""
    u = 2.0 * np.pi * t_s / 5600.0
    r = 6371.2 + 450.0
    lon = np.radians(20.0) - 2.0 * np.pi * t_s / 86164.0
    return np.column_stack(
        [r * np.cos(u) * np.cos(lon), r * np.cos(u) * np.sin(lon), r * np.sin(u)]
    )


def test_thinned_crust_matches_every_sample_far_below_the_noise() -> None:
    t = 1.6e9 + np.arange(0.0, 1500.0, 1.0)
    t = np.delete(
        t, np.r_[300:340, 700:701, 1100:1497]
    )  # a 40 s gap, a dropped sample, a 3-sample stretch
    r = _track(t)
    full = crust(t, r)
    thin = along_track(crust, t, r, CRUST_KNOT_SPACING_S)
    assert float(np.sqrt(np.mean(full**2))) > 1.0  # a crust to interpolate
    err = np.abs(thin - full)
    assert float(err.max()) < 0.01  # nT; sensor noise is 0.1 nT and more
    np.testing.assert_array_equal(thin[-3:], full[-3:])  # too short a stretch: evaluated


def test_data_no_denser_than_the_knots_are_evaluated_at_every_sample() -> None:
    t = 1.6e9 + np.arange(0.0, 2000.0, 10.0)
    r = _track(t)
    np.testing.assert_array_equal(along_track(crust, t, r, CRUST_KNOT_SPACING_S), crust(t, r))
