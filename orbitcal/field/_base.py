"""Field-model interface, the range error, and the piecewise-polynomial spherical-harmonic model."""

from __future__ import annotations

import datetime as _dt
import os
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError, OutOfRangeError
from orbitcal.field._kernel import HAVE_NUMBA, synth_pp_nec_nt
from orbitcal.field.synthesis import n_block_coeffs, synth_internal_nec_nt, to_degree_blocks

__all__ = [
    "UNIX_S_AT_J2000_DAY",
    "FieldModel",
    "FieldRangeError",
    "SphericalHarmonicModel",
    "mjd2000_to_utc_s",
    "utc_s_to_mjd2000",
]


#: POSIX seconds at 2000-01-01T00:00:00 UTC, the origin of "MJD2000" as used by ChaosMagPy
#: (``chaosmagpy.data_utils.mjd2000``: days since 2000-01-01 00:00 UTC, no leap seconds).
UNIX_S_AT_J2000_DAY = 946_684_800.0
_SECONDS_PER_DAY = 86_400.0


def utc_s_to_mjd2000(t_utc_s: FloatArray) -> FloatArray:
    """POSIX seconds of UTC -> days since 2000-01-01 00:00 UTC (MJD2000, no leap seconds)."""
    return (np.asarray(t_utc_s, dtype=np.float64) - UNIX_S_AT_J2000_DAY) / _SECONDS_PER_DAY


def mjd2000_to_utc_s(mjd2000: FloatArray) -> FloatArray:
    """Days since 2000-01-01 00:00 UTC (MJD2000) -> POSIX seconds of UTC."""
    return np.asarray(mjd2000, dtype=np.float64) * _SECONDS_PER_DAY + UNIX_S_AT_J2000_DAY


def _iso(mjd2000: float) -> str:
    t = _dt.datetime(2000, 1, 1, tzinfo=_dt.UTC) + _dt.timedelta(days=float(mjd2000))
    return t.strftime("%Y-%m-%dT%H:%M:%SZ")


def require_in_range(
    mjd: FloatArray, valid_mjd2000: tuple[float, float], *, name: str, advice: str
) -> None:
    """Raise :class:`FieldRangeError` naming the first sample outside ``valid_mjd2000``.

    ``mjd`` are the samples' times [MJD2000]; ``advice`` says what the caller can do.
    """
    start, end = valid_mjd2000
    bad = ~((mjd >= start) & (mjd <= end))
    if np.any(bad):
        i = int(np.argmax(bad))
        when = "not a finite time" if not np.isfinite(mjd[i]) else _iso(mjd[i])
        raise FieldRangeError(
            f"{name} is valid from {_iso(start)} to {_iso(end)}; sample {i} is at {when} "
            f"({int(bad.sum())} samples outside): {advice}"
        )


def _broadcast_samples(
    t_utc_s: FloatArray, radius_km: FloatArray, colat_deg: FloatArray, lon_deg: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Broadcast the four sample arrays against each other and flatten them to (N,)."""
    arrays = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (t_utc_s, radius_km, colat_deg, lon_deg))
    )
    t, r, c, lo = (np.ascontiguousarray(a).reshape(-1) for a in arrays)
    return t, r, c, lo


def _use_numba(backend: str) -> bool:
    if backend == "numpy":
        return False
    if backend == "numba":
        if not HAVE_NUMBA:
            raise BadInputError("backend 'numba' requested but numba is not installed")
        return True
    if backend != "auto":
        raise BadInputError(f"unknown backend {backend!r}; use 'auto', 'numba' or 'numpy'")
    return HAVE_NUMBA and os.environ.get("ORBITCAL_FIELD_BACKEND", "").lower() != "numpy"


class FieldRangeError(OutOfRangeError):
    """A sample time lies outside the validity of a field model.

    Raised with the model name, the first offending date and the valid range; choose another
    model (e.g. a newer IGRF generation) or drop the samples.
    """


@runtime_checkable
class FieldModel(Protocol):
    """A geomagnetic field model evaluated per sample."""

    @property
    def name(self) -> str:
        """Full name with the generation, e.g. ``"IGRF-14"``."""
        ...

    def b_nec_nt(
        self,
        t_utc_s: FloatArray,
        radius_km: FloatArray,
        colat_deg: FloatArray,
        lon_deg: FloatArray,
    ) -> FloatArray:
        """Field at each sample's own time and position.

        Parameters
        ----------
        t_utc_s : ndarray, shape (N,)
            POSIX seconds of UTC.
        radius_km : ndarray, shape (N,)
            Geocentric radius [km].
        colat_deg : ndarray, shape (N,)
            Geocentric colatitude [deg].
        lon_deg : ndarray, shape (N,)
            Longitude east [deg].

        Returns
        -------
        ndarray, shape (N, 3)
            Geocentric North, East, Centre (down) [nT].
        """
        ...


class SphericalHarmonicModel:
    """Internal field with Gauss coefficients piecewise polynomial in time.

    Coefficients are held once, in degree-block layout, as a piecewise polynomial in MJD2000
    (``coeffs_pp[k, piece, :]`` multiplies ``(t - breaks[piece]) ** (order - 1 - k)``, the
    convention of :class:`scipy.interpolate.PPoly`). A static model has ``order = 1`` and no
    time limits.

    Parameters
    ----------
    name : str
        Full model name.
    nmin, nmax : int
        Degree range.
    breaks_mjd2000 : ndarray, shape (P + 1,)
        Piece boundaries [days since 2000-01-01 UTC]; the model is valid between the first and the
        last (inclusive).
    coeffs_pp_flat : ndarray, shape (order, P, nmax (nmax + 2))
        Polynomial coefficients per piece, flat Gauss order [nT day^-k].
    static : bool, optional
        True for a time-independent model (no range check).
    """

    def __init__(
        self,
        name: str,
        *,
        nmin: int,
        nmax: int,
        breaks_mjd2000: FloatArray,
        coeffs_pp_flat: FloatArray,
        static: bool = False,
    ) -> None:
        self._name = name
        self.nmin = nmin
        self.nmax = nmax
        self.breaks_mjd2000 = np.asarray(breaks_mjd2000, dtype=np.float64)
        self.coeffs_pp_flat = np.asarray(coeffs_pp_flat, dtype=np.float64)
        self.order = self.coeffs_pp_flat.shape[0]
        self.static = static
        # (order, P, K) degree blocks: contiguous rows per piece for fast evaluation.
        self._pp_blocks = np.ascontiguousarray(to_degree_blocks(self.coeffs_pp_flat, nmax))

    @property
    def name(self) -> str:
        return self._name

    @property
    def valid_mjd2000(self) -> tuple[float, float]:
        """First and last valid time [MJD2000]; (-inf, inf) for a static model."""
        if self.static:
            return (-np.inf, np.inf)
        return (float(self.breaks_mjd2000[0]), float(self.breaks_mjd2000[-1]))

    def check_range(self, t_utc_s: FloatArray) -> FloatArray:
        """Return MJD2000 of the samples; raise :class:`FieldRangeError` if any is outside."""
        mjd = utc_s_to_mjd2000(t_utc_s).reshape(-1)
        if self.static:
            return mjd
        require_in_range(
            mjd, self.valid_mjd2000, name=self.name, advice="choose a model that covers it"
        )
        return mjd

    def _piece_and_offset(self, mjd: FloatArray) -> tuple[NDArray[np.intp], FloatArray]:
        n_pieces = self.breaks_mjd2000.shape[0] - 1
        idx = np.searchsorted(self.breaks_mjd2000, mjd, side="right") - 1
        np.clip(idx, 0, max(n_pieces - 1, 0), out=idx)
        return idx, mjd - self.breaks_mjd2000[idx]

    def _coeffs_blocks_t(self, idx: NDArray[np.intp], dt: FloatArray) -> FloatArray:
        """Per-sample degree-block coefficients, transposed: (K, n)."""
        k = self._pp_blocks.shape[2]
        out = np.empty((k, idx.shape[0]))
        pieces = np.unique(idx)
        for piece in pieces:
            cols: slice | NDArray[np.bool_] = slice(None) if pieces.size == 1 else idx == piece
            d = dt[cols]
            acc = np.repeat(self._pp_blocks[0, piece][:, None], d.shape[0], axis=1)
            for k_pow in range(1, self.order):
                acc *= d
                acc += self._pp_blocks[k_pow, piece][:, None]
            out[:, cols] = acc
        return out

    def gauss_coeffs(self, t_utc_s: FloatArray) -> FloatArray:
        """Gauss coefficients at each time, flat order ``g10, g11, h11, ..`` (N, nmax(nmax+2)) [nT].

        Raises :class:`FieldRangeError` outside the validity.
        """
        mjd = self.check_range(t_utc_s)
        idx, dt = self._piece_and_offset(mjd)
        c = self.coeffs_pp_flat[0, idx]
        for k_pow in range(1, self.order):
            c = c * dt[:, None] + self.coeffs_pp_flat[k_pow, idx]
        return c

    def b_nec_nt(
        self,
        t_utc_s: FloatArray,
        radius_km: FloatArray,
        colat_deg: FloatArray,
        lon_deg: FloatArray,
    ) -> FloatArray:
        """Field at each sample's own time and position, NEC [nT] (see :class:`FieldModel`)."""
        return self.evaluate(t_utc_s, radius_km, colat_deg, lon_deg)

    def evaluate(
        self,
        t_utc_s: FloatArray,
        radius_km: FloatArray,
        colat_deg: FloatArray,
        lon_deg: FloatArray,
        *,
        backend: str = "auto",
    ) -> FloatArray:
        """:meth:`b_nec_nt` with a choice of implementation.

        Parameters
        ----------
        backend : {"auto", "numba", "numpy"}, keyword-only
            ``"numba"``: the compiled per-sample kernel (:mod:`orbitcal.field._kernel`);
            ``"numpy"``: the chunked vectorised recursion (:mod:`orbitcal.field.synthesis`);
            ``"auto"``: numba when installed, unless the environment variable
            ``ORBITCAL_FIELD_BACKEND`` says ``numpy``.
        """
        t_utc_s, radius_km, colat_deg, lon_deg = _broadcast_samples(
            t_utc_s, radius_km, colat_deg, lon_deg
        )
        mjd = self.check_range(t_utc_s)
        idx, dt = self._piece_and_offset(mjd)
        if _use_numba(backend):
            return synth_pp_nec_nt(
                self._pp_blocks,
                idx.astype(np.int64, copy=False),
                dt,
                radius_km,
                np.radians(colat_deg),
                np.radians(lon_deg),
                nmin=self.nmin,
                nmax=self.nmax,
            )
        if self.order == 1 and self._pp_blocks.shape[1] == 1:
            return synth_internal_nec_nt(
                self._pp_blocks[0, 0], radius_km, colat_deg, lon_deg, nmax=self.nmax, nmin=self.nmin
            )

        def provider(start: int, stop: int) -> FloatArray:
            return self._coeffs_blocks_t(idx[start:stop], dt[start:stop])

        return synth_internal_nec_nt(
            provider, radius_km, colat_deg, lon_deg, nmax=self.nmax, nmin=self.nmin
        )

    @property
    def n_coeffs(self) -> int:
        """Number of degree-block coefficients per sample."""
        return n_block_coeffs(self.nmax)

    def __repr__(self) -> str:
        return f"SphericalHarmonicModel({self.name!r}, nmin={self.nmin}, nmax={self.nmax})"
