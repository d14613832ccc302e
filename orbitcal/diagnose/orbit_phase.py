"""The attitude error as a function of orbital phase: star-tracker head switches.

A star tracker is blinded by the Sun, the Earth or the Moon at about the same place of every
orbit, and the attitude solution then switches heads (or to the gyros). Each head has its own
small misalignment, so the attitude error is a step function of the orbital phase: ``dtheta``
takes one value over the part of the orbit (the *window*) another head is used, and it does so
again on the next orbit. No sum of three sinusoids (:mod:`~orbitcal.diagnose.attitude_scan`)
follows such steps, and a step function of fixed bins leaves a box at each switch that falls
inside a bin (24 bins left 2.4 times the noise across B on an independent world). So the window
is found by a scan: for every window of the orbital phase (start and length on a grid of
:data:`PHASE_GRID` steps, then a finer grid around the best), the gain of its three columns
``1[phase in window] (e_k x B)`` on the training residual of the calibration alone, projected off
the calibration's columns, all windows at once from cumulative sums over the samples sorted by
phase. The constant part of ``dtheta`` is a misalignment the calibration absorbs.

A window seen on fewer than :data:`MIN_ORBITS` orbits of the training span cannot be told from
whatever else happened then, so the form needs that much training span.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attitude_scan import _rotation_columns
from orbitcal.diagnose.calibration_columns import calibration_rows
from orbitcal.diagnose.columns import FunctionColumns, Index
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.design import DesignBlock

__all__ = [
    "MIN_ORBITS",
    "MIN_WINDOW",
    "MU_EARTH_KM3_S2",
    "PHASE_GRID",
    "design_attitude_by_phase",
    "orbit_phase",
    "orbital_period_s",
]

#: The Earth's gravitational parameter [km^3/s^2] (WGS-84).
MU_EARTH_KM3_S2 = 398600.4418

#: Steps of the orbital phase on the scan's coarse grid (16 s of a 94 min orbit), and of its fine
#: grid around the best window (4 s).
PHASE_GRID = 360
PHASE_FINE = 1440
#: The shortest window, as a fraction of the orbit: a star tracker's Sun and Earth exclusion
#: half-cones are 25-45 deg, so a head is blinded for at least ~1/20 of an orbit; a shorter window
#: follows a few samples (a spike at the same phase of two orbits named it on a null world with
#: spiky noise, tuning seed 20014 no. 33: a window of 1/1000 orbit).
MIN_WINDOW = 1.0 / 24.0
#: Windows the scan chooses among (coarse grid, then the fine grid around the best).
_SHORTEST = round(MIN_WINDOW * PHASE_GRID)
#: The fine grid's steps either side of the best window's start and end.
_FINE_HALF = 4
WINDOWS_SEARCHED = PHASE_GRID * (PHASE_GRID // 2 - _SHORTEST + 1) + (2 * _FINE_HALF + 1) ** 2
#: Orbits the training span must cover for the form to be written.
MIN_ORBITS = 1.5
#: At most this many training samples enter the scan (every k-th).
SCAN_MAX_SAMPLES = 20_000


def orbital_period_s(data: DiagnosisData) -> float:
    """The period of a circular orbit at the track's mean geocentric distance [s]."""
    r_km = float(np.mean(np.linalg.norm(data.r_itrs_km, axis=1)))
    return float(2.0 * np.pi * np.sqrt(r_km**3 / MU_EARTH_KM3_S2))


def orbit_phase(data: DiagnosisData) -> FloatArray:
    """Orbital phase per sample in [0, 1): the time since the last ascending node over the time
    between it and the next (before the first node and after the last one, over the mean period
    between nodes, or a circular orbit's period at the track's mean distance)."""
    t = data.t_utc_s
    z = data.r_itrs_km[:, 2]
    up = np.flatnonzero((z[:-1] < 0.0) & (z[1:] >= 0.0) & (np.diff(t) > 0.0))
    nodes = t[up] + (t[up + 1] - t[up]) * (-z[up]) / (z[up + 1] - z[up])
    period = float(np.mean(np.diff(nodes))) if nodes.size >= 2 else orbital_period_s(data)
    if nodes.size == 0:
        return np.asarray(((t - t[0]) / period) % 1.0)
    k = np.searchsorted(nodes, t, side="right") - 1
    phase = ((t - nodes[0]) / period) % 1.0
    last = nodes.size - 1
    between = (k >= 0) & (k < last)
    kb = k[between]
    phase[between] = (t[between] - nodes[kb]) / (nodes[kb + 1] - nodes[kb])
    after = k >= last
    phase[after] = ((t[after] - nodes[last]) / period) % 1.0
    return np.asarray(np.clip(phase, 0.0, np.nextafter(1.0, 0.0)))


def design_attitude_by_phase(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """``dtheta`` (per mrad) inside the window of the orbital phase the scan finds, zero outside
    it; None when the training span covers fewer than :data:`MIN_ORBITS` orbits."""
    idx = np.flatnonzero(train)
    if idx.size < 12:
        return None
    if float(data.t_utc_s[idx[-1]] - data.t_utc_s[idx[0]]) < MIN_ORBITS * orbital_period_s(data):
        return None
    phase = orbit_phase(data)
    window = _best_window(data, idx[:: max(1, -(-idx.size // SCAN_MAX_SAMPLES))], phase)
    if window is None:
        return None
    start, length = window
    return DesignBlock(
        FunctionColumns(data.n, 3, partial(_window_columns, data, phase, start, length)),
        [f"dtheta_phase_{axis}_mrad" for axis in "xyz"],
        variant=f"orbit phase {start:.3f}-{(start + length) % 1.0:.3f}",
        searched=2,
        forms_searched=WINDOWS_SEARCHED,
    )


def _in_window(phase: FloatArray, start: float, length: float) -> BoolArray:
    return np.asarray(((phase - start) % 1.0) < length)


def _window_columns(
    data: DiagnosisData, phase: FloatArray, start: float, length: float, index: Index
) -> FloatArray:
    """``1[phase in window] (e_k x B) 1e-3`` at the samples ``index``, (m, 3, 3)."""
    inside = _in_window(phase[index], start, length).astype(float)
    cols = _rotation_columns(data, index)
    return np.asarray(cols * (1e-3 * inside)[:, None, None])


def _best_window(
    data: DiagnosisData, idx: np.ndarray, phase: FloatArray
) -> tuple[float, float] | None:
    """The window (start, length; phase in [0, 1)) of greatest gain, coarse then fine grid."""
    x = calibration_rows(data, idx)
    q, _ = np.linalg.qr(x)
    y = data.b_raw_nt[idx].reshape(-1)
    r = y - q @ (q.T @ y)
    m = idx.size
    rot = 1e-3 * _rotation_columns(data, idx)  # per mrad
    q3 = q.reshape(m, 3, -1)
    # per sample: M = R^T R (3x3), K = Q^T R (12x3), v = R^T r (3), summed by window below
    per = np.concatenate(
        [
            np.einsum("mia,mib->mab", rot, rot).reshape(m, 9),
            np.einsum("miq,mia->mqa", q3, rot).reshape(m, -1),
            np.einsum("mia,mi->ma", rot, r.reshape(m, 3)),
        ],
        axis=1,
    )
    order = np.argsort(phase[idx], kind="stable")
    ph = phase[idx][order]
    # two turns of the orbit, so that a window may wrap past the ascending node
    cum = np.vstack([np.zeros((1, per.shape[1])), np.cumsum(np.vstack([per[order]] * 2), axis=0)])
    ph2 = np.concatenate([ph, ph + 1.0])
    starts = np.arange(PHASE_GRID) / PHASE_GRID
    lengths = np.arange(_SHORTEST, PHASE_GRID // 2 + 1) / PHASE_GRID
    gain, best = _window_gains(cum, ph2, starts, lengths)
    if best is None:
        return None
    a, w = best
    fine = np.arange(-_FINE_HALF, _FINE_HALF + 1) / PHASE_FINE
    ends = (a + w) + fine
    fine_starts = (a + fine) % 1.0
    best_fine: tuple[float, float] | None = None
    top = -np.inf
    for s0 in fine_starts:
        lens = np.sort((ends - s0) % 1.0)
        lens = lens[(lens >= MIN_WINDOW) & (lens <= 1.0 - MIN_WINDOW)]
        if lens.size == 0:
            continue
        g, b = _window_gains(cum, ph2, np.array([s0]), lens)
        if b is not None and g > top:
            top, best_fine = g, b
    return best_fine if best_fine is not None and top >= gain else best


def _window_gains(
    cum: FloatArray, ph2: FloatArray, starts: FloatArray, lengths: FloatArray
) -> tuple[float, tuple[float, float] | None]:
    """The largest gain over windows ``starts x lengths`` and its window."""
    lo = np.searchsorted(ph2, starts, side="left")
    hi = np.searchsorted(ph2, starts[:, None] + lengths[None, :], side="left")
    sums = cum[hi] - cum[lo][:, None, :]  # (starts, lengths, 9 + 3 q + 3)
    n_q = (cum.shape[1] - 12) // 3
    mm = sums[..., :9].reshape(*sums.shape[:2], 3, 3)
    kk = sums[..., 9 : 9 + 3 * n_q].reshape(*sums.shape[:2], n_q, 3)
    v = sums[..., 9 + 3 * n_q :]
    g = mm - np.einsum("slqa,slqb->slab", kk, kk)
    tr = np.trace(g, axis1=2, axis2=3)
    g = g + (1e-9 * tr + 1e-300)[..., None, None] * np.eye(3)
    sol = np.linalg.solve(g, v[..., None])[..., 0]
    gains = np.einsum("sla,sla->sl", v, sol)
    gains[~np.isfinite(gains)] = 0.0
    i, j = np.unravel_index(int(np.argmax(gains)), gains.shape)
    if not gains[i, j] > 0.0:
        return 0.0, None
    return float(gains[i, j]), (float(starts[i]), float(lengths[j]))
