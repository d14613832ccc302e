"""Vectorised spherical-harmonic synthesis of internal and external potential fields.

Every sample carries its own position and, optionally, its own Gauss coefficients (so a
time-dependent model is evaluated at each sample's own time, never on an N dates × N points grid).
The Schmidt semi-normalised associated Legendre functions are built by the standard three-term
recursion in degree, vectorised over the points of a chunk and over the orders of one degree, so
the Python loop runs ``nmax`` times per chunk (Langel 1987, "The main field", in *Geomagnetism*
vol. 1, eqs. 4.7–4.9; the same recursion as ``chaosmagpy.model_utils.legendre_poly``).

Layout of a coefficient vector in this module ("degree blocks"): for each degree
``n = 1 .. nmax`` a block of ``2 (n + 1)`` numbers ``g_n0, g_n1, .., g_nn, 0, h_n1, .., h_nn``
(``h_n0`` is a zero placeholder). :func:`to_degree_blocks` converts from the usual flat order
``g10, g11, h11, g20, g21, h21, ..`` used by .shc files and chaosmagpy.

Conventions: geocentric spherical coordinates, radius [km], colatitude θ [deg], longitude φ [deg]
east; output North, East, Centre (down) [nT]: ``B_N = -B_θ``, ``B_E = B_φ``, ``B_C = -B_r``.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import FloatArray

__all__ = [
    "CHUNK_SIZE",
    "EARTH_REFERENCE_RADIUS_KM",
    "block_offsets",
    "n_block_coeffs",
    "synth_internal_nec_nt",
    "to_degree_blocks",
]

#: Reference radius of the geomagnetic potential expansions [km] (IGRF-14 and CHAOS, Alken et al.
#: 2021 "International Geomagnetic Reference Field: the thirteenth generation", EPS 73:49, sec. 2).
EARTH_REFERENCE_RADIUS_KM = 6371.2

#: Samples per chunk: bounds the working memory (about 100 B per sample per degree) independently
#: of N and keeps the arrays of one degree in the CPU cache.
CHUNK_SIZE = 2048

#: Points closer to a pole than this colatitude [rad] are evaluated at it (the field changes by
#: far less than 1e-6 nT; it avoids 0/0 in B_φ).
_POLE_EPS_RAD = 1e-9

#: Per-chunk coefficient provider: (start, stop) sample indices -> (K, stop - start) degree blocks
#: (transposed: orders along axis 0, points along axis 1).
CoeffProvider = Callable[[int, int], FloatArray]


def n_block_coeffs(nmax: int) -> int:
    """Length of a degree-block coefficient vector up to degree ``nmax`` (``nmax(nmax+3)``)."""
    return sum(2 * (n + 1) for n in range(1, nmax + 1))


def block_offsets(nmax: int) -> list[int]:
    """Start of each degree's block; ``offsets[n - 1]`` for degree ``n``."""
    offsets = []
    start = 0
    for n in range(1, nmax + 1):
        offsets.append(start)
        start += 2 * (n + 1)
    return offsets


@lru_cache(maxsize=8)
def _flat_to_block_index(nmax: int) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Index into the flat vector for every block slot, and the mask of placeholder slots."""
    index = np.zeros(n_block_coeffs(nmax), dtype=np.intp)
    placeholder = np.zeros(n_block_coeffs(nmax), dtype=bool)
    for n, off in zip(range(1, nmax + 1), block_offsets(nmax), strict=True):
        flat0 = n * n - 1  # index of g_n0 in the flat order
        index[off] = flat0
        for m in range(1, n + 1):
            index[off + m] = flat0 + 2 * m - 1  # g_nm
            index[off + n + 1 + m] = flat0 + 2 * m  # h_nm
        placeholder[off + n + 1] = True
    return index, placeholder


def to_degree_blocks(coeffs_flat: FloatArray, nmax: int) -> FloatArray:
    """Convert flat Gauss coefficients ``(..., nmax(nmax+2))`` to degree blocks ``(..., K)``.

    Parameters
    ----------
    coeffs_flat : ndarray, shape (..., nmax (nmax + 2))
        ``g10, g11, h11, g20, g21, h21, g22, h22, ..`` [nT].
    nmax : int
        Maximum degree.

    Returns
    -------
    ndarray, shape (..., nmax (nmax + 3))
        Degree blocks (see the module docstring) [nT].
    """
    coeffs_flat = np.asarray(coeffs_flat, dtype=np.float64)
    if coeffs_flat.shape[-1] != nmax * (nmax + 2):
        raise ValueError(
            f"expected {nmax * (nmax + 2)} coefficients for nmax={nmax}, "
            f"got {coeffs_flat.shape[-1]}"
        )
    index, placeholder = _flat_to_block_index(nmax)
    out = coeffs_flat[..., index]
    out[..., placeholder] = 0.0
    return out


@lru_cache(maxsize=8)
def _recursion_constants(
    nmax: int,
) -> tuple[list[FloatArray], list[FloatArray], list[float], list[FloatArray]]:
    """Per degree n: A_n[m], B_n[m] (m < n), diagonal factor D_n and the orders m = 0..n."""
    a_list: list[FloatArray] = []
    b_list: list[FloatArray] = []
    d_list: list[float] = []
    m_list: list[FloatArray] = []
    for n in range(1, nmax + 1):
        m = np.arange(n, dtype=np.float64)
        den = np.sqrt(n * n - m * m)
        a_list.append((2 * n - 1) / den)
        b = np.sqrt(np.clip((n - 1) ** 2 - m * m, 0.0, None)) / den
        b_list.append(b)
        d_list.append(1.0 if n == 1 else float(np.sqrt((2 * n - 1) / (2 * n))))
        m_list.append(np.arange(n + 1, dtype=np.float64))
    return a_list, b_list, d_list, m_list


def _synth_chunk(
    coeffs: FloatArray,
    radius_km: FloatArray,
    colat_rad: FloatArray,
    lon_rad: FloatArray,
    nmin: int,
    nmax: int,
    out: FloatArray,
) -> None:
    """Add the internal field of one chunk to ``out`` (chunk, 3) NEC [nT].

    ``coeffs`` is (K,) or (K, chunk): orders run along axis 0, points along axis 1, so that the
    slices of one degree are contiguous rows.
    """
    a_list, b_list, d_list, m_list = _recursion_constants(nmax)
    offsets = block_offsets(nmax)
    per_sample = coeffs.ndim == 2
    npts = radius_km.shape[0]

    theta = np.clip(colat_rad, _POLE_EPS_RAD, np.pi - _POLE_EPS_RAD)
    x = np.cos(theta)
    s = np.sin(theta)
    mphi = np.arange(nmax + 1, dtype=np.float64)[:, None] * lon_rad[None, :]
    cosm = np.cos(mphi)
    sinm = np.sin(mphi)
    ar = EARTH_REFERENCE_RADIUS_KM / radius_km
    rr = ar * ar  # (a/r)^(n+2) after the update at degree n

    b_r = np.zeros(npts)
    b_t = np.zeros(npts)
    b_p = np.zeros(npts)

    # Level n-1 and n-2 arrays carry one trailing zero row (P_{n-1}^{n} = 0).
    p_prev = np.zeros((2, npts))
    p_prev[0] = 1.0
    dp_prev = np.zeros((2, npts))
    p_prev2 = np.zeros((1, npts))
    dp_prev2 = np.zeros((1, npts))
    xs = x * 0.0  # scratch

    for n in range(1, nmax + 1):
        p = np.empty((n + 2, npts))
        dp = np.empty((n + 2, npts))
        a_n = a_list[n - 1][:, None]
        # m = 0 .. n-1: P_n^m = A x P_{n-1}^m - B P_{n-2}^m ;
        # dP_n^m = A (x dP_{n-1}^m - s P_{n-1}^m) - B dP_{n-2}^m
        pv = p_prev[:n]
        dpv = dp_prev[:n]
        pn_ = p[:n]
        dpn_ = dp[:n]
        np.multiply(pv, x, out=pn_)
        np.multiply(dpv, x, out=dpn_)
        dpn_ -= pv * s
        if n >= 2:
            b_n = b_list[n - 1][:, None]
            pn_ *= a_n
            pn_ -= b_n * p_prev2[:n]
            dpn_ *= a_n
            dpn_ -= b_n * dp_prev2[:n]
        # diagonal m = n
        d_n = d_list[n - 1]
        p_last = p_prev[n - 1]
        np.multiply(s, p_last, out=p[n])
        p[n] *= d_n
        np.multiply(s, dp_prev[n - 1], out=dp[n])
        np.multiply(x, p_last, out=xs)
        dp[n] += xs
        dp[n] *= d_n
        p[n + 1] = 0.0
        dp[n + 1] = 0.0

        rr = rr * ar
        if n >= nmin:
            off = offsets[n - 1]
            if per_sample:
                g = coeffs[off : off + n + 1]
                h = coeffs[off + n + 1 : off + 2 * n + 2]
            else:
                g = coeffs[off : off + n + 1, None]
                h = coeffs[off + n + 1 : off + 2 * n + 2, None]
            c = cosm[: n + 1]
            sn = sinm[: n + 1]
            t1 = g * c
            t1 += h * sn  # g cos mφ + h sin mφ
            t2 = h * c
            t2 -= g * sn
            t2 *= m_list[n - 1][:, None]  # ∂/∂φ of t1
            pn = p[: n + 1]
            b_r += ((n + 1) * rr) * np.einsum("ij,ij->j", pn, t1)
            b_t -= rr * np.einsum("ij,ij->j", dp[: n + 1], t1)
            b_p -= rr * np.einsum("ij,ij->j", pn, t2)

        p_prev2, dp_prev2 = p_prev, dp_prev
        p_prev, dp_prev = p, dp

    out[:, 0] -= b_t
    out[:, 1] += b_p / s
    out[:, 2] -= b_r


def synth_internal_nec_nt(
    coeffs: FloatArray | CoeffProvider,
    radius_km: FloatArray,
    colat_deg: FloatArray,
    lon_deg: FloatArray,
    *,
    nmax: int,
    nmin: int = 1,
    chunk_size: int = CHUNK_SIZE,
) -> FloatArray:
    """Internal potential field at N points, each with its own coefficients if given so.

    Parameters
    ----------
    coeffs : ndarray, shape (K,) or (N, K), or callable
        Gauss coefficients in degree blocks (:func:`to_degree_blocks`) [nT]: one set for all
        points, one row per point, or ``provider(start, stop) -> (K, stop - start)`` (note the
        transpose) called once per chunk, so per-sample coefficients never exist for all N at once.
    radius_km : ndarray, shape (N,)
        Geocentric radius [km].
    colat_deg : ndarray, shape (N,)
        Geocentric colatitude [deg].
    lon_deg : ndarray, shape (N,)
        Longitude, east [deg]. The three position arrays broadcast against each other.
    nmax : int
        Maximum degree (``K = nmax (nmax + 3)``).
    nmin : int, optional
        Degrees below ``nmin`` are left out (their coefficients are ignored).
    chunk_size : int, optional
        Points per chunk.

    Returns
    -------
    ndarray, shape (N, 3)
        Field in geocentric North, East, Centre (down) [nT].
    """
    r_b, c_b, l_b = np.broadcast_arrays(
        np.asarray(radius_km, dtype=np.float64),
        np.asarray(colat_deg, dtype=np.float64),
        np.asarray(lon_deg, dtype=np.float64),
    )
    radius_km = np.ascontiguousarray(r_b).reshape(-1)
    colat_rad = np.radians(c_b).reshape(-1)
    lon_rad = np.radians(l_b).reshape(-1)
    npts = radius_km.shape[0]
    k = n_block_coeffs(nmax)
    out = np.zeros((npts, 3))
    static: FloatArray | None = None
    provider: CoeffProvider | None = None
    if callable(coeffs):
        provider = coeffs
    else:
        arr = np.asarray(coeffs, dtype=np.float64)
        if arr.shape[-1] != k:
            raise ValueError(f"expected {k} degree-block coefficients for nmax={nmax}")
        if arr.ndim == 1:
            static = arr
        else:
            if arr.shape[0] != npts:
                raise ValueError("per-sample coefficients need one row per point")

            def provider(start: int, stop: int, _arr: FloatArray = arr) -> FloatArray:
                return np.ascontiguousarray(_arr[start:stop].T)

    for start in range(0, npts, chunk_size):
        stop = min(start + chunk_size, npts)
        chunk_coeffs = static if static is not None else provider(start, stop)  # type: ignore[misc]
        _synth_chunk(
            chunk_coeffs,
            radius_km[start:stop],
            colat_rad[start:stop],
            lon_rad[start:stop],
            nmin,
            nmax,
            out[start:stop],
        )
    return out
