"""Joining products on time: interpolation inside each product's span, never past it.

A magnetometer sample takes its attitude, position and housekeeping from the products' own
samples that bracket it. Where a product has no sample on one side (before its first, after its
last) or the bracketing samples are further apart than the product's allowed gap, the sample is
dropped and counted by reason — nothing is extrapolated or bridged.

* quaternions: spherical linear interpolation (slerp) on the shorter arc;
* positions: cubic Hermite interpolation with the product's own velocities (exact for a cubic
  trajectory; a few millimetres over a 1 s GNSS step in low orbit);
* scalar housekeeping (temperatures): linear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray, IntArray

__all__ = ["Bracket", "bracket", "hermite_positions", "linear", "slerp"]


@dataclass(frozen=True)
class Bracket:
    """Where samples fall among a product's sample times.

    Attributes
    ----------
    index : ndarray of int, shape (N,)
        ``i`` with ``t_aux[i] <= t < t_aux[i + 1]`` (``t == t_aux[-1]`` takes the last interval).
    frac : ndarray, shape (N,)
        ``(t − t_aux[i]) / (t_aux[i+1] − t_aux[i])`` in [0, 1].
    step_s : ndarray, shape (N,)
        ``t_aux[i+1] − t_aux[i]`` [s].
    before, after, in_gap : ndarray of bool, shape (N,)
        Samples before the first product sample, after the last one, or in an interval longer
        than the allowed gap; ``ok`` is none of these.
    """

    index: IntArray
    frac: FloatArray
    step_s: FloatArray
    before: BoolArray
    after: BoolArray
    in_gap: BoolArray

    def take(self, idx: IntArray) -> Bracket:
        """The same for the samples ``idx`` only."""
        return Bracket(
            self.index[idx],
            self.frac[idx],
            self.step_s[idx],
            self.before[idx],
            self.after[idx],
            self.in_gap[idx],
        )

    @property
    def ok(self) -> BoolArray:
        """Samples that can be interpolated."""
        return ~(self.before | self.after | self.in_gap)


def bracket(t_s: FloatArray, t_aux_s: FloatArray, *, max_gap_s: float) -> Bracket:
    """Locate ``t_s`` among the sorted, strictly increasing product times ``t_aux_s`` [s]."""
    t = np.asarray(t_s, dtype=np.float64)
    ta = np.asarray(t_aux_s, dtype=np.float64)
    n_aux = ta.shape[0]
    if n_aux < 2:
        none = np.zeros(t.shape, dtype=bool)
        return Bracket(
            np.zeros(t.shape, np.int64),
            np.zeros_like(t),
            np.zeros_like(t),
            np.ones(t.shape, dtype=bool) if n_aux == 0 else t < ta[0],
            none if n_aux == 0 else t > ta[0],
            none if n_aux == 0 else t == ta[0],
        )
    i = np.searchsorted(ta, t, side="right") - 1
    before = i < 0
    after = (i >= n_aux - 1) & (t > ta[-1])
    i = np.clip(i, 0, n_aux - 2)
    step = ta[i + 1] - ta[i]
    frac = np.clip((t - ta[i]) / step, 0.0, 1.0)
    in_gap = (step > max_gap_s) & ~before & ~after
    return Bracket(i.astype(np.int64), frac, step, before, after, in_gap)


def slerp(q_wxyz: FloatArray, b: Bracket) -> FloatArray:
    """Quaternions at the bracketed times by slerp between neighbours, shape (N, 4), unit norm.

    ``q`` and ``−q`` are the same rotation: the second neighbour is flipped onto the first's
    hemisphere, so the interpolation takes the shorter arc.
    """
    q0 = q_wxyz[b.index]
    q1 = q_wxyz[b.index + 1]
    dot = np.einsum("ij,ij->i", q0, q1)
    q1 = np.where(dot[:, None] < 0.0, -q1, q1)
    dot = np.abs(dot).clip(max=1.0)
    theta = np.arccos(dot)
    s = np.sin(theta)
    small = s < 1e-9
    safe = np.where(small, 1.0, s)
    f = b.frac
    w0 = np.where(small, 1.0 - f, np.sin((1.0 - f) * theta) / safe)
    w1 = np.where(small, f, np.sin(f * theta) / safe)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return np.asarray(q / np.linalg.norm(q, axis=1, keepdims=True), dtype=np.float64)


def hermite_positions(r: FloatArray, v: FloatArray, b: Bracket) -> FloatArray:
    """Positions at the bracketed times by cubic Hermite interpolation, shape (N, 3).

    Parameters
    ----------
    r : ndarray, shape (M, 3)
        The product's positions (any length unit).
    v : ndarray, shape (M, 3)
        The product's velocities (that unit per second).
    b : Bracket
        From :func:`bracket` on the product's times.
    """
    i = b.index
    h = b.step_s[:, None]
    s = b.frac[:, None]
    s2 = s * s
    s3 = s2 * s
    h00 = 2 * s3 - 3 * s2 + 1
    h10 = s3 - 2 * s2 + s
    h01 = -2 * s3 + 3 * s2
    h11 = s3 - s2
    return np.asarray(
        h00 * r[i] + h10 * h * v[i] + h01 * r[i + 1] + h11 * h * v[i + 1], dtype=np.float64
    )


def linear(y: FloatArray, b: Bracket) -> FloatArray:
    """A scalar series at the bracketed times by linear interpolation, shape (N,)."""
    return np.asarray(y[b.index] * (1.0 - b.frac) + y[b.index + 1] * b.frac, dtype=np.float64)
