"""Compiled (Numba) per-sample synthesis kernel: the fast path of :mod:`orbitcal.field.synthesis`.

One loop over samples; for each, the Gauss coefficients are evaluated from the model's piecewise
polynomial at the sample's own time (Horner), and the Schmidt semi-normalised Legendre functions
come from the same three-term recursion as the numpy path (Langel 1987, eqs. 4.7–4.9). No array
grows with the number of samples except the output. ``HAVE_NUMBA`` is False when Numba cannot be
imported; the numpy path is then used.
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["HAVE_NUMBA", "max_threads", "synth_pp_nec_nt"]

try:  # pragma: no cover - exercised by whichever branch is installed
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None  # type: ignore[assignment]
    HAVE_NUMBA = False

_EARTH_REFERENCE_RADIUS_KM = 6371.2  # same constant as orbitcal.field.synthesis
_POLE_EPS_RAD = 1e-9


def _constants(nmax: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Constants of the Schmidt recursion (Langel 1987, eqs. 4.7–4.9)."""
    width = nmax + 2
    a_c = np.zeros((nmax + 1, width))
    b_c = np.zeros((nmax + 1, width))
    d_c = np.ones(nmax + 1)
    for n in range(1, nmax + 1):
        for m in range(n):
            den = math.sqrt(n * n - m * m)
            a_c[n, m] = (2 * n - 1) / den
            if (n - 1) * (n - 1) > m * m:
                b_c[n, m] = math.sqrt((n - 1) * (n - 1) - m * m) / den
        if n >= 2:
            d_c[n] = math.sqrt((2 * n - 1) / (2 * n))
    return a_c, b_c, d_c


def _kernel_range(
    pp: NDArray[np.float64],
    piece: NDArray[np.int64],
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    a_c: NDArray[np.float64],
    b_c: NDArray[np.float64],
    d_c: NDArray[np.float64],
    start: int,
    stop: int,
    out: NDArray[np.float64],
) -> None:
    """Samples ``start:stop``, with scratch arrays of their own (one call per thread)."""
    order = pp.shape[0]
    width = nmax + 2
    # P[n, m] and dP/dθ[n, m] of the current sample, one row per degree (row n has a zero at
    # m = n + 1 so that the recursion may read P[n-2, m] for m up to n - 1 without a branch).
    pnm = np.zeros((nmax + 1, width))
    dpnm = np.zeros((nmax + 1, width))
    cosm = np.zeros(nmax + 1)
    sinm = np.zeros(nmax + 1)
    coef = np.zeros(pp.shape[2])
    for i in range(start, stop):
        j = piece[i]
        d = dt[i]
        for k in range(coef.shape[0]):
            c = pp[0, j, k]
            for o in range(1, order):
                c = c * d + pp[o, j, k]
            coef[k] = c
        theta = min(max(colat_rad[i], _POLE_EPS_RAD), math.pi - _POLE_EPS_RAD)
        x = math.cos(theta)
        s = math.sin(theta)
        cp = math.cos(lon_rad[i])
        sp = math.sin(lon_rad[i])
        cosm[0] = 1.0
        sinm[0] = 0.0
        for m in range(1, nmax + 1):
            cosm[m] = cosm[m - 1] * cp - sinm[m - 1] * sp
            sinm[m] = sinm[m - 1] * cp + cosm[m - 1] * sp
        ar = _EARTH_REFERENCE_RADIUS_KM / radius_km[i]
        rr = ar * ar
        pnm[0, 0] = 1.0
        pnm[0, 1] = 0.0
        dpnm[0, 0] = 0.0
        dpnm[0, 1] = 0.0
        b_r = 0.0
        b_t = 0.0
        b_p = 0.0
        off = 0
        for n in range(1, nmax + 1):
            if n == 1:
                pnm[1, 0] = x
                dpnm[1, 0] = -s
            else:
                for m in range(n):
                    pnm[n, m] = a_c[n, m] * x * pnm[n - 1, m] - b_c[n, m] * pnm[n - 2, m]
                    dpnm[n, m] = (
                        a_c[n, m] * (x * dpnm[n - 1, m] - s * pnm[n - 1, m])
                        - b_c[n, m] * dpnm[n - 2, m]
                    )
            pnm[n, n] = d_c[n] * s * pnm[n - 1, n - 1]
            dpnm[n, n] = d_c[n] * (s * dpnm[n - 1, n - 1] + x * pnm[n - 1, n - 1])
            pnm[n, n + 1] = 0.0
            dpnm[n, n + 1] = 0.0
            rr *= ar
            if n >= nmin:
                sr = 0.0
                st = 0.0
                sph = 0.0
                for m in range(n + 1):
                    g = coef[off + m]
                    h = coef[off + n + 1 + m]
                    t1 = g * cosm[m] + h * sinm[m]
                    t2 = m * (h * cosm[m] - g * sinm[m])
                    sr += pnm[n, m] * t1
                    st += dpnm[n, m] * t1
                    sph += pnm[n, m] * t2
                b_r += (n + 1) * rr * sr
                b_t -= rr * st
                b_p -= rr * sph
            off += 2 * (n + 1)
        out[i, 0] += -b_t
        out[i, 1] += b_p / s
        out[i, 2] += -b_r


def _kernel_serial(
    pp: NDArray[np.float64],
    piece: NDArray[np.int64],
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    out: NDArray[np.float64],
) -> None:
    a_c, b_c, d_c = _constants(nmax)
    _range_fn(
        pp, piece, dt, radius_km, colat_rad, lon_rad, nmin, nmax, a_c, b_c, d_c, 0,
        radius_km.shape[0], out,
    )  # fmt: skip


def _kernel_parallel(
    pp: NDArray[np.float64],
    piece: NDArray[np.int64],
    dt: NDArray[np.float64],
    radius_km: NDArray[np.float64],
    colat_rad: NDArray[np.float64],
    lon_rad: NDArray[np.float64],
    nmin: int,
    nmax: int,
    n_chunks: int,
    out: NDArray[np.float64],
) -> None:
    a_c, b_c, d_c = _constants(nmax)
    n_pts = radius_km.shape[0]
    for c in _prange(n_chunks):
        _range_fn(
            pp, piece, dt, radius_km, colat_rad, lon_rad, nmin, nmax, a_c, b_c, d_c,
            c * n_pts // n_chunks, (c + 1) * n_pts // n_chunks, out,
        )  # fmt: skip


_prange: Any = range
_range_fn: Any = _kernel_range
_compiled: Any = None
_compiled_parallel: Any = None
if HAVE_NUMBA:
    # fastmath without "nnan"/"ninf": reassociation lets the order sums vectorise; inputs stay IEEE.
    _FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
    _prange = numba.prange

    def _jit(fn: Any, **kw: Any) -> Any:
        try:
            return numba.njit(
                cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy", **kw
            )(fn)
        except RuntimeError:  # pragma: no cover - no writable cache location (read-only install)
            return numba.njit(
                cache=False, nogil=True, fastmath=_FASTMATH, error_model="numpy", **kw
            )(fn)

    _constants = _jit(_constants)
    _range_fn = _jit(_kernel_range)
    _compiled = _jit(_kernel_serial)
    _compiled_parallel = _jit(_kernel_parallel, parallel=True)

#: Below this many samples per thread the threads cost more than they save (one thread).
MIN_SAMPLES_PER_THREAD = 20_000

#: Chunks per thread: a thread slowed by another job on its core leaves work for the others.
CHUNKS_PER_THREAD = 8

# The parallel kernel is entered by one caller at a time (numba's default "workqueue" threading
# layer is not safe for concurrent launches); a caller that finds it busy runs the serial kernel.
_PARALLEL_LOCK = threading.Lock()


def _numba_threads() -> int:
    """Numba's thread pool size (``NUMBA_NUM_THREADS``, default: every core)."""
    return int(numba.config.NUMBA_NUM_THREADS) if HAVE_NUMBA else 1  # type: ignore[attr-defined]


def max_threads() -> int:
    """Threads the parallel kernel may use: ``ORBITCAL_FIELD_THREADS`` if set, else every core
    numba sees (bounded by numba's own ``NUMBA_NUM_THREADS``)."""
    if not HAVE_NUMBA:
        return 1
    limit = _numba_threads()
    env = os.environ.get("ORBITCAL_FIELD_THREADS")
    if env:
        with contextlib.suppress(ValueError):
            return max(1, min(limit, int(env)))
    return limit


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
    samples per thread). Each sample's arithmetic is the serial kernel's: results do not depend
    on the thread count.

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
    args = (
        np.ascontiguousarray(pp_blocks, dtype=np.float64),
        np.ascontiguousarray(piece, dtype=np.int64),
        np.ascontiguousarray(dt_days, dtype=np.float64),
        np.ascontiguousarray(radius_km, dtype=np.float64),
        np.ascontiguousarray(colat_rad, dtype=np.float64),
        np.ascontiguousarray(lon_rad, dtype=np.float64),
        int(nmin),
        int(nmax),
    )
    cap = max_threads() if threads is None else min(threads, _numba_threads())
    n_threads = min(cap, n_pts // MIN_SAMPLES_PER_THREAD)
    if n_threads >= 2 and _PARALLEL_LOCK.acquire(blocking=False):
        try:
            previous = numba.get_num_threads()
            numba.set_num_threads(n_threads)
            try:
                _compiled_parallel(*args, n_threads * CHUNKS_PER_THREAD, out)
            finally:
                numba.set_num_threads(previous)
        finally:
            _PARALLEL_LOCK.release()
        return out
    _compiled(*args, out)
    return out
