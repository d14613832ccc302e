"""Which injected effects the data can show at all: an observability oracle for ``run_worlds.py``.

Shares no code with ``orbitcal``. An injected effect is *observable* when the world with only it
(every other injected effect drawn but not applied, ``make_world(..., exclude=...)``) leaves a
held-out residual of the 12-parameter calibration at least :data:`OBSERVABLE_GAIN` above the
world with none -- the definition of the project's own compound benchmark
(``orbitcal/diagnose/bench.py``), here with this generator's worlds and its own least squares.
The reference field is what a user computes: IGRF-14 at the positions of the element set they
hold, rotated into the body frame with the attitude the table gives. The calibration is fitted
on the first 70 % of the samples and judged on the last 30 % (the diagnosis's default held-out
blocks are the later 30 % of the samples).

An effect that is not observable in this sense -- a sensor temperature that settles before the
held-out blocks begin, a time-tag error under nadir pointing whose field the calibration's
matrix absorbs -- leaves no gap for any diagnosis to name, and a miss of it is counted apart.
"""

from __future__ import annotations

import numpy as np
from world import (
    TleSet,
    World,
    gcrs_to_itrs_matrices,
    igrf14_itrs_nt,
    make_world,
    propagate_itrs_km,
)

#: Least held-out gain over the world without any injected effect [-] (the project's own
#: benchmark uses the same 3 %).
OBSERVABLE_GAIN = 0.03
#: Later fraction of the samples held out [-].
HOLDOUT_FRACTION = 0.3


def reference_body_nt(world: World, tle: TleSet) -> np.ndarray:
    """IGRF-14 at the positions of ``tle``, in the body frame of the table's attitude [nT]."""
    t = world.t_unix_s
    b_itrs = igrf14_itrs_nt(t, propagate_itrs_km(tle, t))
    b_gcrs = np.einsum("nji,nj->ni", gcrs_to_itrs_matrices(t), b_itrs)
    return world.body_to_gcrs.inv().apply(b_gcrs)


def calibration_holdout_rms_nt(b_raw_nt: np.ndarray, b_ref_nt: np.ndarray) -> float:
    """RMS per component of the held-out residual of a 12-parameter linear calibration
    (``b_raw = A b_ref + o``) fitted on the earlier samples [nT]."""
    n = b_raw_nt.shape[0]
    cut = round(n * (1.0 - HOLDOUT_FRACTION))
    x = np.column_stack([b_ref_nt, np.ones(n)])
    coef, *_ = np.linalg.lstsq(x[:cut], b_raw_nt[:cut], rcond=None)
    r = b_raw_nt[cut:] - x[cut:] @ coef
    return float(np.sqrt(np.mean(r**2)))


def observability(
    seed: list[int], effects: list[str], noise: str = "white", small_unmodelled: bool = False
) -> dict[str, dict]:
    """For each of ``effects``: the held-out RMS of the world with only it, of the world with
    none, and whether it is observable. ``seed``, ``noise`` and ``small_unmodelled`` as the
    world was made with."""
    every = frozenset(effects)

    def world(exclude: frozenset[str]) -> tuple[World, TleSet]:
        rng = np.random.default_rng(seed)
        w = make_world(
            rng, effects, noise=noise, small_unmodelled=small_unmodelled, exclude=exclude
        )
        assert w.tle_truth is not None
        return w, w.tle_truth

    none, truth = world(every)
    floor = calibration_holdout_rms_nt(none.b_raw_nt, reference_body_nt(none, truth))
    out: dict[str, dict] = {}
    for name in effects:
        alone, truth = world(every - {name})
        # the orbit error is the user's element set; without it they would hold the truth's
        tle = alone.tle_given if name == "orbit_error" else truth
        rms = calibration_holdout_rms_nt(alone.b_raw_nt, reference_body_nt(alone, tle))
        out[name] = {
            "holdout_rms_alone_nt": round(rms, 4),
            "holdout_rms_none_nt": round(floor, 4),
            "observable": bool(rms >= floor * (1.0 + OBSERVABLE_GAIN)),
        }
    return out
