"""The noise of a residual: its white-noise floor and its isolated samples (spikes).

The floor (:func:`noise_floor_nt`) is read from second differences, which slow signals cancel
in. An *isolated* sample is a single sample far from both neighbours.

A telemetry spike, a sample whose time tag is wrong, or a field structure narrower than one
sample step puts one sample of the residual far from the samples beside it. A few such samples
carry a held-out mean square on their own: on the independent generator's spiky null worlds
(0.5 % of the samples hit by 300 nT) the final residual was 8.9-36.8 nT per component, 3.8-25 x
the noise floor, and the report said "an unexplained gap ... it lies mostly in eclipse" of
data whose every other sample was at the noise floor (`benchmarks/results/diagnose_independent.md`).
The gap section (:func:`orbitcal.diagnose.gap.gap_section`) leaves them out of its figures and
says how many there were and how large; the split fits
(:mod:`orbitcal.diagnose.attribution.split_fits`) read the correlation of a residual without
them.

A sample is *isolated* when a component of it differs by more than :data:`ISOLATED_SIGMAS`
white-noise standard deviations from the median of the five samples around it (the run of
contiguous samples mirrored at its ends) and from each neighbour it has, while neither neighbour
is so far from its own median: two or more such samples in a row are a structure, not a spike,
and stay.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.data import contiguous_runs

__all__ = [
    "ISOLATED_SIGMAS",
    "despiked",
    "isolated_samples",
    "noise_floor_nt",
    "without_isolated",
]

#: A component more than this many white-noise standard deviations from the running median of
#: five samples marks its sample [-]. For white noise a sample's distance from that median has a
#: standard deviation of about 1.2 sigma, so 8 sigma is ~6.7 of them: about 1e-11 per component.
ISOLATED_SIGMAS = 8.0
#: Samples of the running median.
_WINDOW = 5


def noise_floor_nt(residual_nt: FloatArray, mask: BoolArray | None = None) -> float:
    """White-noise level of a residual per component [nT] from its second differences.

    For white noise of standard deviation sigma, ``r[k+1] - 2 r[k] + r[k-1]`` has standard
    deviation ``sqrt(6) sigma``; slow signals (an orbit-scale mismatch, a drift) cancel in it. The
    median absolute value (``0.6745 sigma`` for a normal variable) keeps spikes and short auroral
    structures from raising the estimate. Second differences across a gap are not used.
    """
    r = np.asarray(residual_nt, dtype=float)
    idx = np.flatnonzero(mask) if mask is not None else np.arange(r.shape[0])
    if idx.size < 8:
        return float("nan")
    consecutive = (np.diff(idx[:-1]) == 1) & (np.diff(idx[1:]) == 1)
    d2 = r[idx[2:]] - 2.0 * r[idx[1:-1]] + r[idx[:-2]]
    d2 = d2[consecutive]
    if d2.shape[0] < 5:
        return float("nan")
    per_axis = np.median(np.abs(d2), axis=0) / 0.6745 / np.sqrt(6.0)
    return float(np.sqrt(np.mean(per_axis**2)))


def _running_median(seg: FloatArray) -> FloatArray:
    """Median of the five samples around each sample of one contiguous run (mirrored at its
    ends, three samples on a run of three or four), (m, 3)."""
    size = min(_WINDOW, seg.shape[0] - (1 - seg.shape[0] % 2))
    if size <= 1:
        return np.array(seg, dtype=float)
    half = size // 2
    # numpy's "reflect" is scipy.ndimage's "mirror" (the end sample not repeated); numpy's own
    # windows stand in for ``median_filter`` (the whole run was no faster for it, see
    # benchmarks/results/diagnose_timing.md)
    padded = np.pad(np.asarray(seg, dtype=float), ((half, half), (0, 0)), mode="reflect")
    windows = np.lib.stride_tricks.sliding_window_view(padded, size, axis=0)
    return np.asarray(np.median(windows, axis=-1))


def isolated_samples(residual_nt: FloatArray, t_s: FloatArray, sigma_nt: float) -> BoolArray:
    """The isolated samples of ``residual_nt`` (N, 3) at times ``t_s`` [s], given the white-noise
    standard deviation ``sigma_nt`` per component [nT] (none when it is not finite)."""
    r = np.asarray(residual_nt, dtype=float)
    out = np.zeros(r.shape[0], dtype=bool)
    if not np.isfinite(sigma_nt) or sigma_nt <= 0.0:
        return out
    for run in contiguous_runs(np.asarray(t_s, dtype=float)):
        seg = r[run]
        if seg.shape[0] < 3:
            continue
        limit = ISOLATED_SIGMAS * sigma_nt
        far = np.max(np.abs(seg - _running_median(seg)), axis=1) > limit
        # and far from each neighbour it has (not one side of a step beside a spike)
        jump = np.max(np.abs(np.diff(seg, axis=0)), axis=1) > limit
        far[1:] &= jump
        far[:-1] &= jump
        beside = np.zeros_like(far)
        beside[1:] |= far[:-1]
        beside[:-1] |= far[1:]
        out[run] = far & ~beside
    return out


def without_isolated(residual_nt: FloatArray, t_s: FloatArray, isolated: BoolArray) -> FloatArray:
    """``residual_nt`` with each isolated sample replaced by the running median around it."""
    r = np.array(residual_nt, dtype=float)
    if not np.any(isolated):
        return r
    for run in contiguous_runs(np.asarray(t_s, dtype=float)):
        seg = r[run]
        hit = isolated[run]
        if seg.shape[0] < 3 or not np.any(hit):
            continue
        seg[hit] = _running_median(seg)[hit]
    return r


def despiked(residual_nt: FloatArray, t_s: FloatArray) -> FloatArray:
    """``residual_nt`` (N, 3) with its isolated samples (against its own noise floor) replaced
    by the running median around them: what tests that read a field's size or correlation from
    mean squares should read (a 500 nT spike among 500 auroral-zone samples adds 22 nT to their
    RMS)."""
    spikes = isolated_samples(residual_nt, t_s, noise_floor_nt(residual_nt))
    if not np.any(spikes):
        return np.asarray(residual_nt, dtype=float)
    return without_isolated(residual_nt, t_s, spikes)
