"""The attitude-error scan: the periods of the sinusoids of ``dtheta(t)`` found on the data.

An attitude error ``db = dtheta x B`` with ``dtheta`` a sum of up to three sinusoids and a drift
(linear over the training span, held at its last value after it): the periods are chosen by a
scan of the training residual (a beam search with refinement passes), alone or beside effects
already selected (:attr:`orbitcal.diagnose.effects.Effect.design_beside`), and their number by
how well each set forecasts the end of the training span from the rest.

Until 2026-11-27 there was no drift, periods reached 80 % of the training span (and the
refinement passes went beyond it), and the three periods the scan fitted best were kept. The
independent generator's attitude error (a twice-per-orbit flex and a random walk) was then
followed on the training blocks by periods of 16,000-20,000 s or by beating pairs of close
periods, whose continuation into the held-out blocks was a guess: 17 of 36 attitude errors
were missed on seeds 10400-10900 (`benchmarks/results/diagnose_independent.md`).
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.calibration_columns import calibration_rows
from orbitcal.diagnose.columns import (
    FunctionColumns,
    Index,
    triangular_factor,
)
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.design import DesignBlock

__all__ = ["ATTITUDE_PERIODS_S", "AttitudeScan", "design_attitude"]


#: Periods scanned for the attitude-error sinusoids [s] (log-spaced), and how many are kept.
ATTITUDE_PERIODS_S = np.geomspace(1200.0, 30000.0, 160)
ATTITUDE_MAX_TERMS = 3
#: The longest period scanned, as a fraction of the training span: a sinusoid with fewer than two
#: cycles on the training blocks cannot be told from a drift there, and its continuation into the
#: held-out blocks (after the training span) is a guess. The refinement passes keep to it too.
ATTITUDE_MAX_PERIOD_FRACTION = 0.5
#: Two periods of a set beat at ``1/|1/p1 - 1/p2|``; with less than this many cycles of their beat
#: on the training span, the pair is one sinusoid whose amplitude the fit shapes at will (it
#: follows any slow wander there, and its continuation after the span is a guess). Two sinusoids
#: ``d`` cycles apart over the span correlate about ``sinc(d)`` there: 0.64 at half a cycle, 0.998
#: at 0.034 (independent world 9500 no. 8 fitted 11,527 and 11,824 s); our simulator's 5,400 and
#: 7,020 s are 0.67 cycles apart on 4.3 h of training.
ATTITUDE_MIN_BEAT_CYCLES = 0.5
#: The period sets carried by the beam search are judged by a fit to the first this fraction of
#: the training span, scored on the rest (:meth:`AttitudeScan.forward_rss`).
ATTITUDE_FORWARD_SPLIT = 0.7
#: A set of more periods is kept only when its forward residual sum of squares beats every set of
#: fewer periods by more than this fraction: an extra sinusoid that follows a wander of the
#: training residual predicts the end of the training span a little better, and the held-out
#: blocks after it worse.
ATTITUDE_FORWARD_TOLERANCE = 0.25
#: At most this many passes of the cyclic period refinement (it stops at the first pass that
#: changes no period).
ATTITUDE_REFINE_PASSES = 8
#: Sets of periods carried from one greedy step of the scan to the next (beam search).
ATTITUDE_BEAM = 3

#: The rows of the scan's orthonormal basis (and their products K with the rotation columns) are
#: kept between their uses when the rows of Q take at most this size [B].
SCAN_Q_CACHE_BYTES = 16 * 2**20

#: Samples per block of the batched period scan (memory ~ periods x block x 8 B per array).
SCAN_BLOCK_SAMPLES = 4096

#: At most this many training samples enter the period scan (every k-th): the shortest period
#: scanned (1,200 s) then still has ~100 samples per cycle on a day at 1 Hz, and the scan costs
#: the same beyond. The regressors of the periods found use every sample.
SCAN_MAX_SAMPLES = 5_000


def _rotation_columns(data: DiagnosisData, index: Index | None = None) -> FloatArray:
    """e_k x B (k = x, y, z): field change of a small rotation about body axis k, (N, 3, 3)
    (of the samples ``index`` only, if given)."""
    b = data.b_ref_body_nt if index is None else data.b_ref_body_nt[index]
    return np.stack([np.cross(np.eye(3)[k], b) for k in range(3)], axis=2)


def design_attitude(
    data: DiagnosisData, train: BoolArray, *, fixed: Sequence[DesignBlock] = ()
) -> DesignBlock | None:
    """The attitude error's design: the sinusoids of the periods a scan of the training residual
    finds (None when the span is too short or no period gains anything).

    A slowly varying small rotation dtheta(t) of the attitude: db = dtheta x B. The constant part
    is a misalignment the 12 parameters absorb; the variation is a few sinusoids (thermal
    distortion, star-tracker errors) whose periods are found by a matching-pursuit scan of the
    training residual (periods shorter than half the training span), and a drift: linear over
    the training span and held at its last value after it, the best forecast of a wander (a
    random walk of the attitude error, which no sinusoid continues). Beside effects already
    selected (``fixed``), their regressors are projected out with the calibration's and the
    drift's: each period's gain is then what it adds to a joint fit of them all. The number of
    periods (one to three; of each number, the set the scan fits best) is the smallest whose fit
    to the first part of the training span predicts its last part nearly as well as any.
    """
    t = data.t_utc_s - float(data.t_utc_s[train][0])
    span = float(t[train][-1]) if np.any(train) else 0.0
    longest = ATTITUDE_MAX_PERIOD_FRACTION * span
    periods = ATTITUDE_PERIODS_S[longest > ATTITUDE_PERIODS_S]
    if periods.size == 0:
        return None
    scan = AttitudeScan(
        data, train, fixed, longest_s=longest, drift=_drift_block(data, train), grid_s=periods
    )
    # The scan needs, per period, only 6 x 6 and 6 x q sums over the samples: the gain of the
    # projected columns P[R c, R s] (P = I - QQ^T, R = rotation columns, c, s = cos, sin) is
    # g^T (G + eps tr(G) I)^-1 g with G = A - B^T B, A = [[sum c^2 M, sum cs M], [., sum s^2 M]],
    # M = R^T R, B = [sum c K, sum s K], K = Q^T R per sample, g = [sum c R^T r, sum s R^T r].
    # All periods of a grid are summed at once, a block of samples at a time. Q (the calibration
    # columns and the sinusoids of the periods kept) is never held whole: it is X R^-1, the
    # columns X built per block and R from a block-updated QR (:class:`AttitudeScan`).
    sets = _beam_search(scan, periods)
    if not sets:
        return None
    # One refinement pass for every set the beam search carried; of each size (one, two, three
    # periods) the set of least training residual. Of these, the smallest whose fit on the
    # first part of the training span predicts its last part (:meth:`AttitudeScan.forward_rss`)
    # nearly as well as any is refined to convergence.
    by_size: dict[int, tuple[float, list[float]]] = {}
    for chosen, rss in (_refine_periods(scan, c, 1) for c in sets):
        if len(chosen) not in by_size or rss < by_size[len(chosen)][0]:
            by_size[len(chosen)] = (rss, chosen)
    forward = {k: scan.forward_rss(chosen) for k, (_, chosen) in by_size.items()}
    size = min(
        k
        for k in forward
        if forward[k] <= (1.0 + ATTITUDE_FORWARD_TOLERANCE) * min(forward.values())
    )
    if fixed:
        # beside other effects, at least as many periods as the attitude error's own scan kept
        size = min(max(size, _periods_alone(data, train)), max(by_size))
    best = by_size[size][1]
    chosen = _refine_periods(scan, best, ATTITUDE_REFINE_PASSES - 1)[0]
    if fixed:
        return _attitude_block(data, train, chosen)
    _remember_alone(_alone_key(data, train), len(chosen))

    def other_sizes() -> list[DesignBlock]:
        # each other number of periods, refined as the chosen one: the model core chooses the
        # number by evidence (the forward rule kept two of three sinusoids whose forecast then
        # drifted out of phase, and the attitude error was withdrawn; docs/design.md)
        return [
            _attitude_block(
                data, train, _refine_periods(scan, by_size[k][1], ATTITUDE_REFINE_PASSES - 1)[0]
            )
            for k in sorted(by_size)
            if k != size
        ]

    return dataclasses.replace(_attitude_block(data, train, chosen), other_sizes=other_sizes)


#: The number of periods the scan kept beside the calibration alone, per data set and training
#: mask (the attribution scans the attitude error alone first, then beside other effects).
_ALONE_PERIODS: dict[int, int] = {}


def _periods_alone(data: DiagnosisData, train: BoolArray) -> int:
    """How many periods :func:`design_attitude` keeps for ``data`` with nothing beside it.

    The number is the attitude error's: beside an effect whose form is not yet right (a bias
    step at the wrong time) the forecast of the end of the training span can prefer fewer
    periods than the error has, and the pair then fails (``tests/test_diagnose_compound.py``:
    a doubled bias step beside three sinusoids, nothing named)."""
    key = _alone_key(data, train)
    if key not in _ALONE_PERIODS:
        alone = design_attitude(data, train)
        _remember_alone(key, 0 if alone is None else (alone.width - 3) // 6)
    return _ALONE_PERIODS[key]


def _alone_key(data: DiagnosisData, train: BoolArray) -> int:
    """What the scan alone reads, hashed (an id could be another data set's once freed)."""
    arrays = (data.t_utc_s, data.b_raw_nt, data.b_ref_body_nt, train)
    return hash(tuple(np.ascontiguousarray(a).tobytes() for a in arrays))


def _remember_alone(key: int, n_periods: int) -> None:
    if len(_ALONE_PERIODS) >= 8:
        _ALONE_PERIODS.clear()
    _ALONE_PERIODS[key] = n_periods


def _training_ends(train: BoolArray, data: DiagnosisData) -> tuple[float, float]:
    """The times of the first and the last training sample [s]."""
    idx = np.flatnonzero(train)
    return float(data.t_utc_s[idx[0]]), float(data.t_utc_s[idx[-1]])


def _drift_columns(data: DiagnosisData, t0_s: float, t1_s: float, index: Index) -> FloatArray:
    """The drift's regressors at the samples ``index``, (m, 3, 3), per mrad: ``f(t)`` 0 at the
    first training sample ``t0_s``, 1 at the last ``t1_s`` and after it."""
    f = np.clip((data.t_utc_s[index] - t0_s) / max(t1_s - t0_s, 1e-9), 0.0, 1.0)
    return np.asarray(_rotation_columns(data, index) * (1e-3 * f)[:, None, None])


def _drift_block(data: DiagnosisData, train: BoolArray) -> DesignBlock:
    """The attitude error's drift as a design block: ``dtheta = d f(t)``, ``f`` of
    :func:`_drift_columns` (part of every block of :func:`_attitude_block`)."""
    return DesignBlock(
        FunctionColumns(data.n, 3, partial(_drift_columns, data, *_training_ends(train, data))),
        [f"dtheta_{axis}_drift_mrad" for axis in "xyz"],
    )


def _first_best(periods_s: FloatArray, g: FloatArray, floor: float) -> tuple[float, float]:
    """The largest gain and the first period with it, if it beats ``floor`` (else ``floor, 0``):
    a sequential scan keeping strictly better gains picks the same one."""
    if g.size == 0:
        return floor, 0.0
    i = int(np.argmax(g))
    if not g[i] > floor:
        return floor, 0.0
    return float(g[i]), float(periods_s[i])


def _gain_peaks(periods_s: FloatArray, g: FloatArray, n: int) -> list[float]:
    """The periods of the ``n`` largest local maxima of the gain over the grid, >= 5 % apart."""
    order = np.argsort(-g, kind="stable")
    out: list[float] = []
    for i in order:
        if len(out) == n or not g[i] > 0.0:
            break
        p = float(periods_s[i])
        left = g[i - 1] if i > 0 else -np.inf
        right = g[i + 1] if i + 1 < g.size else -np.inf
        if g[i] >= left and g[i] >= right and all(abs(p / q - 1.0) >= 0.05 for q in out):
            out.append(p)
    return out


def _refine_periods(
    scan: AttitudeScan, chosen: list[float], passes: int
) -> tuple[list[float], float]:
    """Cyclic refinement: each period re-fitted with the others fixed (close periods that one
    training span cannot resolve at once are separated this way), until a pass changes none;
    the periods and their training residual sum of squares."""
    chosen = list(chosen)
    for _ in range(passes):
        before = list(chosen)
        for j in range(len(chosen)):
            basis = scan.basis(chosen[:j] + chosen[j + 1 :])
            r_now = scan.residual(basis)
            others = chosen[:j] + chosen[j + 1 :]
            grid = scan.within(chosen[j] * np.linspace(0.94, 1.06, 61), others)
            _, p_best = _first_best(grid, scan.gains(grid, r_now, basis), -1.0)
            chosen[j] = p_best if p_best else chosen[j]
        if chosen == before:
            break
    r_end = scan.residual(scan.basis(chosen))
    return chosen, float(r_end @ r_end)


def _beam_search(scan: AttitudeScan, periods: FloatArray) -> list[list[float]]:
    """The sets of periods the greedy steps carried (the best ``ATTITUDE_BEAM`` of one period,
    of two, of three), each step's best first; empty when no period gains anything.

    The sets are carried from step to step (each extended by the best peaks of its gain curve),
    so that a first period that a greedy scan would take from a mixture of several sinusoids
    cannot lock the others out.
    """
    beams: list[tuple[float, list[float]]] = [(0.0, [])]
    carried: list[list[float]] = []
    for _ in range(ATTITUDE_MAX_TERMS):
        grown: list[tuple[float, list[float]]] = []
        for _score, chosen in beams:
            _grow_beam(scan, periods, chosen, grown)
        if not grown:
            break
        grown.sort(key=lambda t: t[0])
        beams = grown[:ATTITUDE_BEAM]
        carried += [chosen for _, chosen in beams]
    return carried


def _grow_beam(
    scan: AttitudeScan,
    periods: FloatArray,
    chosen: list[float],
    grown: list[tuple[float, list[float]]],
) -> None:
    """Append to ``grown`` the set ``chosen`` extended by each of the best peaks of its gain
    curve (a set already in ``grown``, to 1 %, is not added again)."""
    basis = scan.basis(chosen)
    r_now = scan.residual(basis)
    rss_now = float(r_now @ r_now)
    free = scan.within(periods, chosen)
    for start in _gain_peaks(free, scan.gains(free, r_now, basis), ATTITUDE_BEAM):
        # Refine the period on a fine grid (+-2.5 %): phase errors grow over the
        # held-out span.
        fine = scan.within(start * np.linspace(0.975, 1.025, 51), chosen)
        g_fine = scan.gains(fine, r_now, basis)
        i = int(np.argmax(g_fine))
        period, gain = float(fine[i]), float(g_fine[i])
        key = sorted([*chosen, period])
        if any(
            all(abs(a / b - 1.0) < 0.01 for a, b in zip(key, sorted(c), strict=True))
            for _, c in grown
        ):
            continue
        grown.append((rss_now - gain, [*chosen, period]))


def _attitude_block(data: DiagnosisData, train: BoolArray, chosen: list[float]) -> DesignBlock:
    """The sinusoids of the periods ``chosen`` (cos, sin per axis) and the drift
    (:func:`_drift_columns`) as one design block."""
    names = [
        f"dtheta_{axis}_{fname}_{period:.0f}s_mrad"
        for period in chosen
        for fname in ("cos", "sin")
        for axis in "xyz"
    ] + [f"dtheta_{axis}_drift_mrad" for axis in "xyz"]
    fn = partial(_attitude_and_drift, data, *_training_ends(train, data), tuple(chosen))
    return DesignBlock(
        FunctionColumns(data.n, len(names), fn),
        names,
        variant="periods_s=" + ",".join(f"{p:.0f}" for p in chosen) + " and a drift",
    )


def _attitude_and_drift(
    data: DiagnosisData, t0_s: float, t1_s: float, periods_s: tuple[float, ...], index: Index
) -> FloatArray:
    """The columns of :func:`_attitude_block` at the samples ``index``, (m, 3, 6 p + 3)."""
    sines = _attitude_columns(data, t0_s, periods_s, index)
    return np.concatenate([sines, _drift_columns(data, t0_s, t1_s, index)], axis=2)


#: Samples per run of the factored sinusoids in :func:`_cos_sin`.
_TRIG_RUN = 64


def _cos_sin(w_rad_s: FloatArray, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``cos(w t)`` and ``sin(w t)``, (periods, samples).

    On evenly spaced samples ``t = t_j + k dt`` (runs of :data:`_TRIG_RUN`) the exponential
    factors as ``exp(i w t_j) exp(i w k dt)``: one complex exponential per run and per offset
    instead of two per sample, three times faster and equal to ~4e-15 (a product of two
    rounded unit phasors); uneven times are evaluated directly.
    """
    m = t_s.shape[0]
    runs = m // _TRIG_RUN
    if runs >= 2 and m == runs * _TRIG_RUN:
        dt = float(t_s[1] - t_s[0])
        offsets = dt * np.arange(_TRIG_RUN)
        starts = t_s[::_TRIG_RUN]
        if dt > 0.0 and np.array_equal(t_s, (starts[:, None] + offsets[None, :]).reshape(-1)):
            z = (
                np.exp(1j * np.outer(w_rad_s, starts))[:, :, None]
                * np.exp(1j * np.outer(w_rad_s, offsets))[:, None, :]
            ).reshape(w_rad_s.shape[0], m)
            return np.ascontiguousarray(z.real), np.ascontiguousarray(z.imag)
    phase = np.outer(w_rad_s, t_s)
    return np.cos(phase), np.sin(phase)


class AttitudeScan:
    """The training samples of the attitude period scan, read a block at a time.

    A *basis* is the periods kept with ``M`` for the columns ``X`` = (12 calibration columns, the
    regressors of ``fixed``, then cos and sin of each period times the rotation columns):
    ``Q = X M`` is orthonormal and spans what the scan projects out (``M = R^-1`` of ``X = Q R``,
    or its pseudo-inverse when fixed regressors repeat the calibration's); its rows are built per
    block of samples.
    """

    def __init__(
        self,
        data: DiagnosisData,
        train: BoolArray,
        fixed: Sequence[DesignBlock] = (),
        *,
        longest_s: float = np.inf,
        drift: DesignBlock | None = None,
        grid_s: FloatArray | None = None,
    ) -> None:
        self.data = data
        self.longest_s = float(longest_s)
        self.fixed = list(fixed) + ([] if drift is None else [drift])
        # the drift's columns among X's (the last of the fixed ones), for forward_rss
        width = 12 + sum(bl.width for bl in self.fixed)
        self.drift_columns = slice(width - (0 if drift is None else drift.width), width)
        idx = np.flatnonzero(train)
        #: The training span the periods are told apart on [s] (:meth:`within`).
        self.span_s = float(data.t_utc_s[idx[-1]] - data.t_utc_s[idx[0]])
        self.idx = idx[:: max(1, -(-idx.size // SCAN_MAX_SAMPLES))]
        self.t = data.t_utc_s[self.idx] - float(data.t_utc_s[self.idx[0]])
        self.y = data.b_raw_nt[self.idx].reshape(-1)
        self.n = int(self.idx.size)
        # Per block, what no period changes: the rotation columns, their products R^T R and the
        # columns of the calibration and of ``fixed`` (at most SCAN_MAX_SAMPLES samples:
        # ~0.4 MB each for the first two, 0.1 MB per column for the last).
        # the latest basis's rows of Q and K per block (:meth:`_kept`)
        self._kept_of: FloatArray | None = None
        self._per_block: dict[tuple[str, int], FloatArray] = {}
        #: The periods scanned [s], ascending (:meth:`trig`); None: none tabulated.
        self.grid_s = None if grid_s is None else np.asarray(grid_s, dtype=np.float64)
        self._grid_trig: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._rot = [_rotation_columns(data, self.idx[a0:a1]) * 1e-3 for a0, a1 in self.blocks()]
        self._rtr = [np.matmul(np.swapaxes(r, 1, 2), r).reshape(-1, 9) for r in self._rot]
        self._base = [
            np.concatenate(
                [calibration_rows(data, self.idx[a0:a1])]
                + [bl.rows(self.idx[a0:a1]).reshape(-1, bl.width) for bl in self.fixed],
                axis=1,
            )
            for a0, a1 in self.blocks()
        ]

    def forward_rss(self, periods: Sequence[float]) -> float:
        """Residual sum of squares on the last ``1 - ATTITUDE_FORWARD_SPLIT`` of the training
        span of a fit (calibration, ``fixed``, the drift and the sinusoids of ``periods``) to
        the rest of it: how well the set's continuation predicts samples after those it was
        fitted to, as the held-out blocks (after the training span) will ask. The drift is held
        at its value at the split, as after the training span."""
        x = np.concatenate([self.columns(periods, a0, a1) for a0, a1 in self.blocks()], axis=0)
        t_split = ATTITUDE_FORWARD_SPLIT * float(self.t[-1])
        drift = (
            _rotation_columns(self.data, self.idx)
            * (1e-3 * np.minimum(self.t, t_split) / t_split)[:, None, None]
        )
        if self.drift_columns.stop > self.drift_columns.start:
            x[:, self.drift_columns] = drift.reshape(-1, 3)
        else:
            x = np.concatenate([x, drift.reshape(-1, 3)], axis=1)
        early = np.repeat(self.t <= t_split, 3)
        coef = np.linalg.lstsq(x[early], self.y[early], rcond=None)[0]
        r = self.y[~early] - x[~early] @ coef
        return float(r @ r)

    def within(self, periods_s: FloatArray, others: Sequence[float] = ()) -> FloatArray:
        """The periods of ``periods_s`` that may join ``others``: below ``longest_s``, and
        apart from each of ``others`` by 5 % and by :data:`ATTITUDE_MIN_BEAT_CYCLES` cycles of
        their beat over the training span."""
        p = np.asarray(periods_s, dtype=float)
        keep = p < self.longest_s
        for c in others:
            keep &= np.abs(p / c - 1.0) >= 0.05
            keep &= np.abs(1.0 / p - 1.0 / c) * self.span_s >= ATTITUDE_MIN_BEAT_CYCLES
        return np.asarray(p[keep])

    def blocks(self) -> list[tuple[int, int]]:
        return [
            (a, min(a + SCAN_BLOCK_SAMPLES, self.n)) for a in range(0, self.n, SCAN_BLOCK_SAMPLES)
        ]

    def rot(self, a0: int, a1: int) -> FloatArray:
        """Rotation columns per mrad of the block, (m, 3, 3)."""
        return self._rot[a0 // SCAN_BLOCK_SAMPLES]

    def columns(self, periods: Sequence[float], a0: int, a1: int) -> FloatArray:
        """The columns X of the block, (3 m, 12 + fixed + 6 len(periods))."""
        parts = [self._base[a0 // SCAN_BLOCK_SAMPLES]]
        if periods:
            rt, tt = self.rot(a0, a1), self.t[a0:a1]
            for period in periods:
                w = 2 * np.pi / period
                cols = np.concatenate(
                    [rt * np.cos(w * tt)[:, None, None], rt * np.sin(w * tt)[:, None, None]],
                    axis=2,
                )
                parts.append(cols.reshape(-1, 6))
        return np.concatenate(parts, axis=1)

    def basis(self, periods: Sequence[float]) -> tuple[tuple[float, ...], FloatArray]:
        """The periods and ``R^-1`` of their columns (block-updated QR)."""
        width = 12 + sum(bl.width for bl in self.fixed) + 6 * len(periods)
        r = triangular_factor((self.columns(periods, a0, a1) for a0, a1 in self.blocks()), width)
        if not self.fixed:
            return tuple(periods), np.asarray(np.linalg.inv(r))
        # X = Q R = Q U S V': X V S^-1 = Q U, orthonormal on the directions S does not cut.
        _, s, vt = np.linalg.svd(r)
        keep = s > 1e-10 * s[0]
        return tuple(periods), np.asarray(vt[keep].T / s[keep])

    def q_rows(self, basis: tuple[tuple[float, ...], FloatArray], a0: int, a1: int) -> FloatArray:
        """Rows of ``Q`` of the block (its residual and gains read them three times)."""
        return self._kept(
            basis, "q", a0, lambda: np.asarray(self.columns(basis[0], a0, a1) @ basis[1])
        )

    def k_rows(self, basis: tuple[tuple[float, ...], FloatArray], a0: int, a1: int) -> FloatArray:
        """``K = Q^T R`` per sample of the block, (m, 3 q): what :meth:`gains` sums against the
        sinusoids of every period tried (a beam step asks for the gains of one basis on four
        grids of periods)."""

        def build() -> FloatArray:
            m, n_q = a1 - a0, basis[1].shape[1]
            q3 = self.q_rows(basis, a0, a1).reshape(m, 3, n_q)
            rt = self.rot(a0, a1)
            k3 = q3[:, 0, :, None] * rt[:, 0, None, :]
            for i in (1, 2):
                k3 += q3[:, i, :, None] * rt[:, i, None, :]
            return k3.reshape(m, -1)

        return self._kept(basis, "k", a0, build)

    def _kept(
        self,
        basis: tuple[tuple[float, ...], FloatArray],
        kind: str,
        a0: int,
        build: Callable[[], FloatArray],
    ) -> FloatArray:
        """A per-block array (``kind``) of the latest basis: built once and kept while that basis
        is the latest, when its rows of ``Q`` take at most :data:`SCAN_Q_CACHE_BYTES`."""
        if self._kept_of is not basis[1]:
            self._kept_of, self._per_block = basis[1], {}
        out = self._per_block.get((kind, a0))
        if out is None:
            out = build()
            if 3 * self.n * basis[1].shape[1] * 8 <= SCAN_Q_CACHE_BYTES:
                self._per_block[(kind, a0)] = out
        return out

    def trig(self, periods_s: FloatArray, a0: int, a1: int) -> tuple[FloatArray, FloatArray]:
        """``cos(w t)`` and ``sin(w t)`` of the block, (periods, m) (:func:`_cos_sin`). Periods
        of the scan's grid (:attr:`grid_s`, ascending) are read from a table of the whole grid
        built once per block: each step of the beam search asks for the grid less the periods
        it holds."""
        g = self.grid_s
        if g is not None and len(periods_s):
            pos = np.minimum(np.searchsorted(g, periods_s), g.size - 1)
            if np.array_equal(g[pos], periods_s):
                table = self._grid_trig.get(a0)
                if table is None:
                    table = _cos_sin(2 * np.pi / g, self.t[a0:a1])
                    self._grid_trig[a0] = table
                return table[0][pos], table[1][pos]
        return _cos_sin(2 * np.pi / np.asarray(periods_s, dtype=np.float64), self.t[a0:a1])

    def residual(self, basis: tuple[tuple[float, ...], FloatArray]) -> FloatArray:
        """``y - Q Q^T y`` over the training rows, (3 n,)."""
        qty = np.zeros(basis[1].shape[1])
        for a0, a1 in self.blocks():
            qty += self.q_rows(basis, a0, a1).T @ self.y[3 * a0 : 3 * a1]
        out = np.empty_like(self.y)
        for a0, a1 in self.blocks():
            rows = slice(3 * a0, 3 * a1)
            out[rows] = self.y[rows] - self.q_rows(basis, a0, a1) @ qty
        return out

    def gains(
        self,
        periods_s: FloatArray,
        r_now: FloatArray,
        basis: tuple[tuple[float, ...], FloatArray],
    ) -> FloatArray:
        """Gain in fit of the 6 columns of each period, projected off the basis."""
        n_q = basis[1].shape[1]
        p_n = len(periods_s)
        acc_m = np.zeros((3, p_n, 9))
        acc_k = np.zeros((2, p_n, 3 * n_q))
        acc_v = np.zeros((2, p_n, 3))
        for a0, a1 in self.blocks():
            m = a1 - a0
            rt = self.rot(a0, a1)
            m_blk = self._rtr[a0 // SCAN_BLOCK_SAMPLES]
            k_blk = self.k_rows(basis, a0, a1)
            v_blk = np.matmul(r_now[3 * a0 : 3 * a1].reshape(m, 1, 3), rt)[:, 0, :]
            c, s_ = self.trig(periods_s, a0, a1)
            acc_m[0] += (c * c) @ m_blk
            acc_m[1] += (c * s_) @ m_blk
            acc_m[2] += (s_ * s_) @ m_blk
            acc_k[0] += c @ k_blk
            acc_k[1] += s_ @ k_blk
            acc_v[0] += c @ v_blk
            acc_v[1] += s_ @ v_blk
        m3 = acc_m.reshape(3, p_n, 3, 3)
        gram = np.empty((p_n, 6, 6))
        gram[:, :3, :3] = m3[0]
        gram[:, :3, 3:] = m3[1]
        gram[:, 3:, :3] = np.swapaxes(m3[1], 1, 2)
        gram[:, 3:, 3:] = m3[2]
        # B = Q^T [R c, R s]: (p, q, 6), columns in the order (cos x,y,z, sin x,y,z)
        bq = np.concatenate([acc_k[0].reshape(p_n, n_q, 3), acc_k[1].reshape(p_n, n_q, 3)], axis=2)
        gram -= np.einsum("pqa,pqb->pab", bq, bq)
        rhs = np.concatenate([acc_v[0], acc_v[1]], axis=1)
        tr = np.trace(gram, axis1=1, axis2=2)
        reg = gram + 1e-9 * tr[:, None, None] * np.eye(6)
        out = np.zeros(p_n)
        try:
            sol = np.linalg.solve(reg, rhs[:, :, None])[:, :, 0]
            out = np.einsum("pa,pa->p", rhs, sol)
        except np.linalg.LinAlgError:
            for i in range(p_n):
                with contextlib.suppress(np.linalg.LinAlgError):
                    out[i] = float(rhs[i] @ np.linalg.solve(reg[i], rhs[i]))
        return np.asarray(out)


def _attitude_columns(
    data: DiagnosisData, t0_s: float, periods_s: tuple[float, ...], index: Index
) -> FloatArray:
    """The attitude-error regressors of the periods kept at the samples ``index``, (m, 3,
    6 x periods): built when a fit asks for them instead of held for the whole attribution."""
    t = data.t_utc_s[index] - t0_s
    rot = _rotation_columns(data, index) * 1e-3  # per mrad
    g = np.empty((t.shape[0], 3, 6 * len(periods_s)))
    col = 0
    for period in periods_s:
        w = 2 * np.pi / period
        for f in (np.cos(w * t), np.sin(w * t)):
            for k in range(3):
                np.multiply(rot[:, :, k], f[:, None], out=g[:, :, col])
                col += 1
    return g
