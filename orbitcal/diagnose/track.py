"""Smooth functions of the orbit evaluated sparsely along the track and interpolated in time.

A field model's value along an orbit changes over tens of kilometres at the least (a crustal
model to degree 185 at 450 km; the core field's gradient over thousands), while 1 Hz samples are
7.6 km apart: evaluating at every sample spends most of the cost where a cubic spline of a tenth
of the values gives the same numbers to far below the noise. :func:`along_track` evaluates at
knots at most ``spacing_s`` apart and interpolates between them, per stretch without a gap.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from orbitcal.arrays import FloatArray

__all__ = ["along_track"]


def along_track(
    fn: Callable[[FloatArray, FloatArray], FloatArray],
    t_s: FloatArray,
    r_km: FloatArray,
    spacing_s: float,
) -> FloatArray:
    """``fn(t, r)`` at every sample from evaluations at most ``spacing_s`` apart, interpolated.

    Parameters
    ----------
    fn : callable
        ``fn(t_s, r_km) -> values``, shape (m, ...) for m samples; smooth along the track.
    t_s : ndarray, shape (N,)
        Strictly increasing sample times [s].
    r_km : ndarray, shape (N, k)
        Positions [km] (and any further per-sample inputs of ``fn``), passed on row by row.
    spacing_s : float
        Largest time between knots [s].

    Returns
    -------
    ndarray, shape (N, ...)
        Knots are the first sample of every ``spacing_s`` bin of each stretch without a gap
        longer than ``spacing_s``, and its last sample; between them a cubic spline in time
        (not-a-knot ends). A stretch of fewer than four knots, and data no denser than the knots
        (fewer than twice as many samples), are evaluated at every sample: ``fn`` exactly.
    """
    from scipy.interpolate import CubicSpline

    n = t_s.shape[0]
    starts = np.r_[0, np.flatnonzero(np.diff(t_s) > spacing_s) + 1]
    stops = np.r_[starts[1:], n]
    seg = np.repeat(np.arange(starts.size), stops - starts)
    bin_ = np.floor((t_s - t_s[starts][seg]) / spacing_s).astype(np.int64)
    first = np.r_[True, (seg[1:] != seg[:-1]) | (bin_[1:] != bin_[:-1])]
    last = np.r_[seg[1:] != seg[:-1], True]
    knot = first | last
    if int(knot.sum()) * 2 > n:
        return np.asarray(fn(t_s, r_km))
    knots_per_seg = np.bincount(seg, weights=knot, minlength=starts.size)
    at = knot | (knots_per_seg[seg] < 4)
    values = np.asarray(fn(t_s[at], r_km[at]))
    out = np.empty((n, *values.shape[1:]))
    out[at] = values
    where = np.flatnonzero(at)
    for a, b in zip(starts, stops, strict=True):
        if knots_per_seg[seg[a]] < 4:
            continue
        k = where[(where >= a) & (where < b)]
        out[a:b] = CubicSpline(t_s[k] - t_s[a], out[k], axis=0)(t_s[a:b] - t_s[a])
    return out
