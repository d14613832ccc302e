"""Compiled (Numba) per-sample synthesis kernel: the fast path of :mod:`orbitcal.field.synthesis`.

The Schmidt semi-normalised Legendre functions come from the same three-term recursion as the
numpy path (Langel 1987, eqs. 4.7–4.9), run order by order: for each order ``m`` the sectoral
``P_mm`` (from ``P_m-1,m-1``) starts a recursion in degree whose two previous terms stay in
registers, and each term is summed into the field as soon as it exists; ``cos mφ, sin mφ`` advance
by rotation. Nothing is stored per degree. The Gauss coefficients are evaluated from the model's
piecewise polynomial at each sample's own time (Horner in the offset from the start of its piece),
from a copy of the coefficients in the same order-major sequence as the loops read them.

Samples are taken :data:`LANES` at a time when they share a piece of the model (the usual case for
a time series): the lanes' state lives in the rows of one small array, so the loops over lanes are
independent and the compiler turns them into SIMD instructions. For a model linear in time within
a piece (IGRF; static models get a zero slope) one loop over lanes per ``(n, m)`` term does the
recursion, the coefficients and the sums, with the radial factor carried by the Legendre
functions. Other samples (mixed pieces, the tail of a range) go one by one through the same
arithmetic. No array grows with the number of
samples except the output. ``HAVE_NUMBA`` is False when Numba cannot be imported; the numpy path
is then used.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import itertools
import math
import os
import threading
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["HAVE_NUMBA", "LANES", "max_threads", "order_major", "synth_pp_nec_nt"]

try:  # pragma: no cover - exercised by whichever branch is installed
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None  # type: ignore[assignment]
    HAVE_NUMBA = False

_EARTH_REFERENCE_RADIUS_KM = 6371.2  # same constant as orbitcal.field.synthesis
_POLE_EPS_RAD = 1e-9

#: Samples evaluated together (SIMD lanes over samples). With 8 the loops over lanes are unrolled
#: rather than vectorised (Numba leaves LLVM's SLP vectoriser off); 16 to 64 measured alike within
#: the noise of a shared machine, 32 fills AVX-512 registers four times over.
LANES = 32

# Rows of the per-block lane state (one array, so that the compiler sees disjoint rows).
_X, _S, _CP, _SP, _CM, _SM, _PMM, _DPMM, _P1, _P2, _DP1, _DP2 = range(12)
_BR, _BT, _BP, _D, _AR, _RM, _RN, _G, _H, _XA, _SA, _AR2, _N_ROWS = range(12, 25)


@lru_cache(maxsize=8)
def _order_major_index(nmax: int) -> NDArray[np.intp]:
    """Degree-block index of ``g_nm, h_nm`` for ``m = 0..nmax``, ``n = max(m, 1)..nmax``."""
    offsets = [0]
    for n in range(1, nmax):
        offsets.append(offsets[-1] + 2 * (n + 1))
    index = []
    for m in range(nmax + 1):
        for n in range(max(m, 1), nmax + 1):
            off = offsets[n - 1]
            index += [off + m, off + n + 1 + m]
    return np.asarray(index, dtype=np.intp)


def order_major(pp_blocks: NDArray[np.float64], nmax: int) -> NDArray[np.float64]:
    """Coefficients in the order the kernel reads them.

    Parameters
    ----------
    pp_blocks : ndarray, shape (order, P, K)
        Polynomial coefficients per piece in degree blocks, highest power first.
    nmax : int
        Maximum degree.

    Returns
    -------
    ndarray, shape (P, K, max(order, 2))
        ``[piece, 2 j + (0: g, 1: h), power]`` for the ``j``-th ``(m, n)`` pair, ``m`` outer;
        highest power first. A static model (order 1) gets a zero slope, so that it takes the
        kernel's linear-in-time path (``0 * dt + g`` is exactly ``g``).
    """
    picked = np.asarray(pp_blocks, dtype=np.float64)[:, :, _order_major_index(nmax)]
    if picked.shape[0] == 1:
        picked = np.concatenate([np.zeros_like(picked), picked])
    return np.ascontiguousarray(np.transpose(picked, (1, 2, 0)))


@lru_cache(maxsize=8)
def _constants(nmax: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Constants of the Schmidt recursion (Langel 1987, eqs. 4.7–4.9), order-major.

    Returns ``ab`` (shape (nmax (nmax + 1) / 2, 2)): ``a_nm, b_nm`` of
    ``P_nm = a_nm cos θ P_n-1,m - b_nm P_n-2,m`` for ``m = 0..nmax``, ``n = m+1..nmax``; and
    ``d`` (shape (nmax + 1,)): ``P_nn = d_n sin θ P_n-1,n-1``.
    """
    ab = []
    for m in range(nmax + 1):
        for n in range(m + 1, nmax + 1):
            den = math.sqrt(n * n - m * m)
            b = math.sqrt((n - 1) * (n - 1) - m * m) / den if (n - 1) * (n - 1) > m * m else 0.0
            ab.append(((2 * n - 1) / den, b))
    d_c = np.ones(nmax + 1)
    for n in range(2, nmax + 1):
        d_c[n] = math.sqrt((2 * n - 1) / (2 * n))
    ab_arr = np.asarray(ab, dtype=np.float64).reshape(-1, 2)
    ab_arr.setflags(write=False)
    d_c.setflags(write=False)
    return ab_arr, d_c


def _sample(
    ppm: NDArray[np.float64],
    j: int,
    d: float,
    radius_km: float,
    colat_rad: float,
    lon_rad: float,
    nmin: int,
    nmax: int,
    ab: NDArray[np.float64],
    d_c: NDArray[np.float64],
    out: NDArray[np.float64],
    i: int,
) -> None:
    """One sample (piece ``j``, offset ``d`` [day]) added to ``out[i]``: the lanes' arithmetic."""
    order = ppm.shape[2]
    theta = min(max(colat_rad, _POLE_EPS_RAD), math.pi - _POLE_EPS_RAD)
    x = math.cos(theta)
    s = math.sin(theta)
    cp = math.cos(lon_rad)
    sp = math.sin(lon_rad)
    ar = _EARTH_REFERENCE_RADIUS_KM / radius_km
    r_m = ar * ar  # (a/r)^(m+2)
    cm = 1.0
    sm = 0.0
    pmm = 1.0
    dpmm = 0.0
    b_r = 0.0
    b_t = 0.0
    b_p = 0.0
    k = 0
    q = 0
    for m in range(nmax + 1):
        fm = float(m)
        if m >= 1:
            dm = d_c[m]
            dpmm = dm * (s * dpmm + x * pmm)
            pmm = dm * s * pmm
            cm, sm = cm * cp - sm * sp, sm * cp + cm * sp
            r_m *= ar
            if m >= nmin:
                g = 0.0
                h = 0.0
                for o in range(order):
                    g = g * d + ppm[j, k, o]
                    h = h * d + ppm[j, k + 1, o]
                t1 = g * cm + h * sm
                t2 = fm * (h * cm - g * sm)
                b_r += float(m + 1) * r_m * pmm * t1
                b_t -= r_m * dpmm * t1
                b_p -= r_m * pmm * t2
            k += 2
        p1 = pmm
        dp1 = dpmm
        p2 = 0.0
        dp2 = 0.0
        r_n = r_m
        for n in range(m + 1, nmax + 1):
            a = ab[q, 0]
            bb = ab[q, 1]
            q += 1
            p = a * x * p1 - bb * p2
            dp = a * (x * dp1 - s * p1) - bb * dp2
            p2 = p1
            p1 = p
            dp2 = dp1
            dp1 = dp
            r_n *= ar
            if n >= nmin:
                g = 0.0
                h = 0.0
                for o in range(order):
                    g = g * d + ppm[j, k, o]
                    h = h * d + ppm[j, k + 1, o]
                t1 = g * cm + h * sm
                t2 = fm * (h * cm - g * sm)
                b_r += float(n + 1) * r_n * p * t1
                b_t -= r_n * dp * t1
                b_p -= r_n * p * t2
            k += 2
    out[i, 0] += -b_t
    out[i, 1] += b_p / s
    out[i, 2] += -b_r


def _block(
    ppm: NDArray[np.float64],
    j: int,
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    ab: NDArray[np.float64],
    d_c: NDArray[np.float64],
    i0: int,
    v: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Samples ``i0 .. i0 + LANES - 1``, all in piece ``j``; ``v`` (shape (_N_ROWS, LANES)) is
    scratch. Every loop over lanes is independent across lanes (SIMD)."""
    order = ppm.shape[2]
    for b in range(LANES):
        i = i0 + b
        # inputs read once, before any store: each cos/sin pair becomes one sincos call
        theta = min(max(colat_rad[i], _POLE_EPS_RAD), math.pi - _POLE_EPS_RAD)
        lon = lon_rad[i]
        x, s, cp, sp = math.cos(theta), math.sin(theta), math.cos(lon), math.sin(lon)
        v[_D, b] = dt[i]
        v[_X, b] = x
        v[_S, b] = s
        v[_CP, b] = cp
        v[_SP, b] = sp
        ar = _EARTH_REFERENCE_RADIUS_KM / radius_km[i]
        v[_AR, b] = ar
        v[_RM, b] = ar * ar
        v[_CM, b] = 1.0
        v[_SM, b] = 0.0
        v[_PMM, b] = 1.0
        v[_DPMM, b] = 0.0
        v[_BR, b] = 0.0
        v[_BT, b] = 0.0
        v[_BP, b] = 0.0
    k = 0
    q = 0
    for m in range(nmax + 1):
        fm = float(m)
        if m >= 1:
            dm = d_c[m]
            for b in range(LANES):
                x = v[_X, b]
                s = v[_S, b]
                pmm = v[_PMM, b]
                v[_DPMM, b] = dm * (s * v[_DPMM, b] + x * pmm)
                v[_PMM, b] = dm * s * pmm
                cm = v[_CM, b]
                sm = v[_SM, b]
                v[_CM, b] = cm * v[_CP, b] - sm * v[_SP, b]
                v[_SM, b] = sm * v[_CP, b] + cm * v[_SP, b]
                v[_RM, b] *= v[_AR, b]
            if m >= nmin:
                for b in range(LANES):
                    v[_G, b] = 0.0
                    v[_H, b] = 0.0
                for o in range(order):
                    cg = ppm[j, k, o]
                    ch = ppm[j, k + 1, o]
                    for b in range(LANES):
                        v[_G, b] = v[_G, b] * v[_D, b] + cg
                        v[_H, b] = v[_H, b] * v[_D, b] + ch
                f1 = float(m + 1)
                for b in range(LANES):
                    g = v[_G, b]
                    h = v[_H, b]
                    cm = v[_CM, b]
                    sm = v[_SM, b]
                    t1 = g * cm + h * sm
                    t2 = fm * (h * cm - g * sm)
                    rn = v[_RM, b]
                    p = v[_PMM, b]
                    v[_BR, b] += f1 * rn * p * t1
                    v[_BT, b] -= rn * v[_DPMM, b] * t1
                    v[_BP, b] -= rn * p * t2
            k += 2
        for b in range(LANES):
            v[_P1, b] = v[_PMM, b]
            v[_DP1, b] = v[_DPMM, b]
            v[_P2, b] = 0.0
            v[_DP2, b] = 0.0
            v[_RN, b] = v[_RM, b]
        for n in range(m + 1, nmax + 1):
            a = ab[q, 0]
            bb = ab[q, 1]
            q += 1
            for b in range(LANES):
                x = v[_X, b]
                p1 = v[_P1, b]
                dp1 = v[_DP1, b]
                p = a * x * p1 - bb * v[_P2, b]
                dp = a * (x * dp1 - v[_S, b] * p1) - bb * v[_DP2, b]
                v[_P2, b] = p1
                v[_P1, b] = p
                v[_DP2, b] = dp1
                v[_DP1, b] = dp
                v[_RN, b] *= v[_AR, b]
            if n >= nmin:
                for b in range(LANES):
                    v[_G, b] = 0.0
                    v[_H, b] = 0.0
                for o in range(order):
                    cg = ppm[j, k, o]
                    ch = ppm[j, k + 1, o]
                    for b in range(LANES):
                        v[_G, b] = v[_G, b] * v[_D, b] + cg
                        v[_H, b] = v[_H, b] * v[_D, b] + ch
                f1 = float(n + 1)
                for b in range(LANES):
                    g = v[_G, b]
                    h = v[_H, b]
                    cm = v[_CM, b]
                    sm = v[_SM, b]
                    t1 = g * cm + h * sm
                    t2 = fm * (h * cm - g * sm)
                    rn = v[_RN, b]
                    p = v[_P1, b]
                    v[_BR, b] += f1 * rn * p * t1
                    v[_BT, b] -= rn * v[_DP1, b] * t1
                    v[_BP, b] -= rn * p * t2
            k += 2
    for b in range(LANES):
        i = i0 + b
        out[i, 0] += -v[_BT, b]
        out[i, 1] += v[_BP, b] / v[_S, b]
        out[i, 2] += -v[_BR, b]


def _block_linear(
    ppm: NDArray[np.float64],
    j: int,
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    ab: NDArray[np.float64],
    d_c: NDArray[np.float64],
    i0: int,
    v: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """:func:`_block` for a model linear in time within a piece (order 2; IGRF, static models).

    One loop over lanes per ``(n, m)`` does the recursion, the coefficients and the sums, and
    the Legendre functions carry the radial factor: ``P~_nm = (a/r)^(n+2) P_nm`` obeys the
    same recursion with ``cos θ, sin θ`` scaled by ``a/r`` and ``b_nm`` by ``(a/r)^2``.
    """
    for b in range(LANES):
        i = i0 + b
        # inputs read once, before any store: each cos/sin pair becomes one sincos call
        theta = min(max(colat_rad[i], _POLE_EPS_RAD), math.pi - _POLE_EPS_RAD)
        lon = lon_rad[i]
        x, s, cp, sp = math.cos(theta), math.sin(theta), math.cos(lon), math.sin(lon)
        ar = _EARTH_REFERENCE_RADIUS_KM / radius_km[i]
        v[_D, b] = dt[i]
        v[_S, b] = s
        v[_XA, b] = x * ar
        v[_SA, b] = s * ar
        v[_AR2, b] = ar * ar
        v[_CP, b] = cp
        v[_SP, b] = sp
        v[_CM, b] = 1.0
        v[_SM, b] = 0.0
        v[_PMM, b] = ar * ar
        v[_DPMM, b] = 0.0
        v[_BR, b] = 0.0
        v[_BT, b] = 0.0
        v[_BP, b] = 0.0
    k = 0
    q = 0
    for m in range(nmax + 1):
        fm = float(m)
        if m >= 1:
            dm = d_c[m]
            use = 1.0 if m >= nmin else 0.0
            g0 = ppm[j, k, 0] * use
            g1 = ppm[j, k, 1] * use
            h0 = ppm[j, k + 1, 0] * use
            h1 = ppm[j, k + 1, 1] * use
            f1 = float(m + 1)
            for b in range(LANES):
                xa = v[_XA, b]
                sa = v[_SA, b]
                pmm = v[_PMM, b]
                dpmm = dm * (sa * v[_DPMM, b] + xa * pmm)
                pmm = dm * sa * pmm
                v[_DPMM, b] = dpmm
                v[_PMM, b] = pmm
                cm0 = v[_CM, b]
                sm0 = v[_SM, b]
                cm = cm0 * v[_CP, b] - sm0 * v[_SP, b]
                sm = sm0 * v[_CP, b] + cm0 * v[_SP, b]
                v[_CM, b] = cm
                v[_SM, b] = sm
                g = g0 * v[_D, b] + g1
                h = h0 * v[_D, b] + h1
                t1 = g * cm + h * sm
                t2 = fm * (h * cm - g * sm)
                v[_BR, b] += f1 * pmm * t1
                v[_BT, b] -= dpmm * t1
                v[_BP, b] -= pmm * t2
            k += 2
        for b in range(LANES):
            v[_P1, b] = v[_PMM, b]
            v[_DP1, b] = v[_DPMM, b]
            v[_P2, b] = 0.0
            v[_DP2, b] = 0.0
        for n in range(m + 1, nmax + 1):
            a = ab[q, 0]
            bb = ab[q, 1]
            q += 1
            use = 1.0 if n >= nmin else 0.0
            g0 = ppm[j, k, 0] * use
            g1 = ppm[j, k, 1] * use
            h0 = ppm[j, k + 1, 0] * use
            h1 = ppm[j, k + 1, 1] * use
            f1 = float(n + 1)
            for b in range(LANES):
                xa = v[_XA, b]
                p1 = v[_P1, b]
                dp1 = v[_DP1, b]
                bb_ar2 = bb * v[_AR2, b]
                p = a * xa * p1 - bb_ar2 * v[_P2, b]
                dp = a * (xa * dp1 - v[_SA, b] * p1) - bb_ar2 * v[_DP2, b]
                v[_P2, b] = p1
                v[_P1, b] = p
                v[_DP2, b] = dp1
                v[_DP1, b] = dp
                g = g0 * v[_D, b] + g1
                h = h0 * v[_D, b] + h1
                cm = v[_CM, b]
                sm = v[_SM, b]
                t1 = g * cm + h * sm
                t2 = fm * (h * cm - g * sm)
                v[_BR, b] += f1 * p * t1
                v[_BT, b] -= dp * t1
                v[_BP, b] -= p * t2
            k += 2
    for b in range(LANES):
        i = i0 + b
        out[i, 0] += -v[_BT, b]
        out[i, 1] += v[_BP, b] / v[_S, b]
        out[i, 2] += -v[_BR, b]


def _kernel_range(
    ppm: NDArray[np.float64],
    piece: NDArray[np.int64],
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    ab: NDArray[np.float64],
    d_c: NDArray[np.float64],
    start: int,
    stop: int,
    out: NDArray[np.float64],
) -> None:
    """Samples ``start:stop``: full blocks of one piece in lanes, the others one by one."""
    v = np.zeros((_N_ROWS, LANES))
    linear = ppm.shape[2] == 2
    i0 = start
    while i0 + LANES <= stop:
        j = piece[i0]
        same = True
        for i in range(i0 + 1, i0 + LANES):
            if piece[i] != j:
                same = False
                break
        if same and linear:
            _block_linear_fn(
                ppm, j, dt, radius_km, colat_rad, lon_rad, nmin, nmax, ab, d_c, i0, v, out
            )
        elif same:
            _block_fn(ppm, j, dt, radius_km, colat_rad, lon_rad, nmin, nmax, ab, d_c, i0, v, out)
        else:
            for i in range(i0, i0 + LANES):
                _sample_fn(
                    ppm, piece[i], dt[i], radius_km[i], colat_rad[i], lon_rad[i], nmin, nmax,
                    ab, d_c, out, i,
                )  # fmt: skip
        i0 += LANES
    for i in range(i0, stop):
        _sample_fn(
            ppm, piece[i], dt[i], radius_km[i], colat_rad[i], lon_rad[i], nmin, nmax, ab, d_c,
            out, i,
        )  # fmt: skip


_sample_fn: Any = _sample
_block_fn: Any = _block
_block_linear_fn: Any = _block_linear
_range_fn: Any = _kernel_range
_compiled: Any = None
if HAVE_NUMBA:
    # fastmath without "nnan"/"ninf": reassociation lets the lane loops vectorise; inputs stay IEEE.
    _FASTMATH = {"reassoc", "contract", "nsz", "arcp"}

    def _jit(fn: Any, **kw: Any) -> Any:
        try:
            return numba.njit(
                cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy", **kw
            )(fn)
        except RuntimeError:  # pragma: no cover - no writable cache location (read-only install)
            return numba.njit(
                cache=False, nogil=True, fastmath=_FASTMATH, error_model="numpy", **kw
            )(fn)

    _sample_fn = _jit(_sample)
    # inlined in Numba's IR: as a call of its own the block compiles to slower code (measured)
    _block_fn = _jit(_block, inline="always")
    _block_linear_fn = _jit(_block_linear, inline="always")
    _range_fn = _jit(_kernel_range)
    _compiled = _range_fn

#: Below this many samples per thread the threads cost more than they save (one thread).
MIN_SAMPLES_PER_THREAD = 20_000

#: Chunks per thread: a thread slowed by another job on its core leaves work for the others.
CHUNKS_PER_THREAD = 8

# Parallel runs are entered by one caller at a time (so that concurrent callers, e.g. a service's
# request threads, do not oversubscribe the cores); a caller that finds it busy runs serially.
_PARALLEL_LOCK = threading.Lock()
_POOL: concurrent.futures.ThreadPoolExecutor | None = None


def _after_fork_in_child() -> None:
    # a forked child (e.g. a prefork worker) has neither the parent's threads nor its lock holder
    global _POOL, _PARALLEL_LOCK
    _POOL = None
    _PARALLEL_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def _pool() -> concurrent.futures.ThreadPoolExecutor:
    """The worker threads (created on first use; idle workers block, they do not spin)."""
    global _POOL
    if _POOL is None:
        _POOL = concurrent.futures.ThreadPoolExecutor(
            max(1, _cores()), thread_name_prefix="orbitcal-field"
        )
    return _POOL


def _cores() -> int:
    """Cores this process may run on, bounded by ``NUMBA_NUM_THREADS`` if set."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    return min(cores, int(numba.config.NUMBA_NUM_THREADS)) if HAVE_NUMBA else 1  # type: ignore[attr-defined]


def max_threads() -> int:
    """Threads the parallel kernel may use: ``ORBITCAL_FIELD_THREADS`` if set, else every core
    the process may run on (bounded by numba's ``NUMBA_NUM_THREADS``)."""
    if not HAVE_NUMBA:
        return 1
    limit = _cores()
    env = os.environ.get("ORBITCAL_FIELD_THREADS")
    if env:
        with contextlib.suppress(ValueError):
            return max(1, min(limit, int(env)))
    return limit


def _run_parallel(
    args: tuple[Any, ...], n_pts: int, n_threads: int, out: NDArray[np.float64]
) -> None:
    """``n_threads`` workers take chunks of samples in turn until none is left.

    Chunk boundaries fall on multiples of :data:`LANES`, so every sample takes the same path
    (lanes or single) as in a serial run; the kernel releases the GIL, so the workers run on
    separate cores, and a worker slowed by another job on its core leaves chunks to the others.
    """
    n_chunks = n_threads * CHUNKS_PER_THREAD
    n_blocks = n_pts // LANES
    bounds = [(c * n_blocks // n_chunks) * LANES for c in range(n_chunks)] + [n_pts]
    next_chunk = itertools.count()  # next() is atomic under the GIL

    def worker() -> None:
        for c in next_chunk:
            if c >= n_chunks:
                return
            _compiled(*args, bounds[c], bounds[c + 1], out)

    futures = [_pool().submit(worker) for _ in range(n_threads)]
    for f in futures:
        f.result()


def synth_pp_nec_nt(
    pp_blocks: NDArray[np.float64],
    piece: NDArray[np.int64],
    dt_days: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    *,
    nmin: int,
    nmax: int,
    threads: int | None = None,
) -> NDArray[np.float64]:
    """Field of a piecewise-polynomial model, each sample at its own time (compiled).

    Samples are independent, so they are split into chunks run in parallel on up to
    ``threads`` cores (default :func:`max_threads`; at least :data:`MIN_SAMPLES_PER_THREAD`
    samples per thread). Every thread runs the same compiled code and chunks start on multiples of
    :data:`LANES`, so each sample takes the same path: results do not depend on the thread count.

    Parameters
    ----------
    pp_blocks : ndarray, shape (order, P, K)
        Polynomial coefficients per piece in degree blocks, highest power first [nT day^-k].
    piece : ndarray of int64, shape (N,)
        Piece of each sample.
    dt_days : ndarray, shape (N,)
        Time since the start of that piece [day].
    radius_km, colat_rad, lon_rad : ndarray, shape (N,)
        Geocentric radius [km], colatitude [rad], longitude [rad].
    nmin, nmax : int
        Degree range.
    threads : int, optional
        Upper bound on the threads (1: the serial kernel).

    Returns
    -------
    ndarray, shape (N, 3)
        Geocentric North, East, Centre [nT].
    """
    if _compiled is None:  # pragma: no cover
        raise RuntimeError("numba is not installed")
    n_pts = radius_km.shape[0]
    out = np.zeros((n_pts, 3))
    ab, d_c = _constants(int(nmax))
    args = (
        order_major(pp_blocks, int(nmax)),
        np.ascontiguousarray(piece, dtype=np.int64),
        np.ascontiguousarray(dt_days, dtype=np.float64),
        np.ascontiguousarray(radius_km, dtype=np.float64),
        np.ascontiguousarray(colat_rad, dtype=np.float64),
        np.ascontiguousarray(lon_rad, dtype=np.float64),
        int(nmin),
        int(nmax),
        ab,
        d_c,
    )
    cap = max_threads() if threads is None else min(threads, _cores())
    n_threads = min(cap, n_pts // MIN_SAMPLES_PER_THREAD)
    if n_threads >= 2 and _PARALLEL_LOCK.acquire(blocking=False):
        try:
            _run_parallel(args, n_pts, n_threads, out)
        finally:
            _PARALLEL_LOCK.release()
        return out
    _compiled(*args, 0, n_pts, out)
    return out
