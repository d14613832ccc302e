"""CHAOS-8.1 core field (Finlay et al. 2020, "The CHAOS-7 geomagnetic field model and observed
changes in the South Atlantic Anomaly", EPS 72:156; CHAOS-8.1 release of DTU Space, 2024).

The .shc file holds snapshots of an order-6 (quintic) B-spline in time, ``step`` = 5 snapshots per
knot interval. The spline is recovered exactly as ChaosMagPy does (``BaseModel.from_shc``):
snapshot times converted with 365.25 days per year, knots = every ``step``-th snapshot with the
end knots repeated ``order - 1`` times, and the B-spline coefficients from a least-squares fit
through the snapshots (exact, since the snapshots were sampled from that spline). The spline is
stored as a piecewise polynomial and evaluated per sample.
"""

from __future__ import annotations

import math
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from orbitcal.errors import BadInputError
from orbitcal.field._base import SphericalHarmonicModel
from orbitcal.field.shc import read_shc

__all__ = ["DAYS_PER_YEAR_CHAOS", "chaos_core", "field_data_path"]

#: Days per decimal year in the CHAOS .shc time axis (ChaosMagPy ``from_shc`` default
#: ``leap_year=False``: ``mjd2000 = (dyear - 2000) * 365.25``).
DAYS_PER_YEAR_CHAOS = 365.25


def field_data_path(filename: str) -> Path:
    """Path of a model file shipped in ``orbitcal/field/data/``."""
    return Path(str(resources.files("orbitcal.field.data").joinpath(filename)))


@lru_cache(maxsize=2)
def chaos_core(name: str = "CHAOS-8.1") -> SphericalHarmonicModel:
    """The CHAOS-8.1 core field (n ≤ 20), valid 1997-02-07 .. 2025-02-07 (its spline knots)."""
    if name != "CHAOS-8.1":
        raise BadInputError(f"unknown CHAOS core model {name!r}; available: CHAOS-8.1")
    shc = read_shc(field_data_path("CHAOS-8.1_core.shc"))
    order = shc.order
    step = max(shc.step, 1)
    times = (shc.times_dyear - 2000.0) * DAYS_PER_YEAR_CHAOS
    breaks = times[::step]
    end = ((times.size - 1) // step) * step + 1
    knots = np.pad(breaks, order - 1, mode="edge")
    from scipy import interpolate  # imported here: ~0.4 s that IGRF users never need

    spline = interpolate.make_lsq_spline(times[:end], shc.coeffs_flat[:end], knots, k=order - 1)
    # Piecewise-polynomial form: Taylor coefficients at the left end of every piece (the spline
    # is right-continuous there), highest power first as in scipy.interpolate.PPoly.
    degree = order - 1
    left = breaks[:-1]
    coeffs_pp = np.stack(
        [spline(left, nu=k) / math.factorial(k) for k in range(degree, -1, -1)]
    )  # (order, pieces, K)
    return SphericalHarmonicModel(
        name,
        nmin=shc.nmin,
        nmax=shc.nmax,
        breaks_mjd2000=breaks,
        coeffs_pp_flat=coeffs_pp,
    )
