"""Reader for the SHC format of spherical-harmonic field models (IGRF, CHAOS, LCS-1, MF7).

Format (as written by ChaosMagPy's ``save_shcfile`` and the IGRF/DTU distributions): ``#`` comment
lines, then a parameter line ``nmin nmax N order step [start end]``, a line of ``N`` snapshot
times in decimal years, and one line per coefficient ``n m c_1 .. c_N`` with ``m < 0`` meaning
``h_n|m|``. ``order`` is the order of the piecewise polynomial in time (1 = piecewise constant,
2 = linear, 6 = quintic B-spline for CHAOS) and ``step`` the number of snapshots per spline piece.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from orbitcal.errors import UnreadableInputError

__all__ = ["ShcFile", "read_shc"]


@dataclass(frozen=True)
class ShcFile:
    """Contents of an SHC file.

    Attributes
    ----------
    path : Path
        File read.
    nmin, nmax : int
        Degree range.
    order : int
        Piecewise-polynomial order in time (1 constant, 2 linear, ...).
    step : int
        Snapshots per polynomial piece.
    times_dyear : ndarray, shape (N,)
        Snapshot times [decimal year].
    coeffs_flat : ndarray, shape (N, nmax (nmax + 2))
        Gauss coefficients ``g10, g11, h11, g20, ..`` per snapshot, zero below ``nmin`` [nT].
    """

    path: Path
    nmin: int
    nmax: int
    order: int
    step: int
    times_dyear: NDArray[np.float64]
    coeffs_flat: NDArray[np.float64]


@lru_cache(maxsize=16)
def read_shc(path: str | Path) -> ShcFile:
    """Read an SHC file once (cached by path).

    Parameters
    ----------
    path : str or Path
        The .shc file.

    Returns
    -------
    ShcFile
    """
    path = Path(path)
    params: list[int] | None = None
    times: NDArray[np.float64] | None = None
    rows: list[NDArray[np.float64]] = []
    with path.open() as fh:
        for line in fh:
            stripped = line.strip()
            if not stripped or stripped.startswith("#"):
                continue
            if params is None:
                params = [int(float(v)) for v in stripped.split()[:5]]
                continue
            values = np.array(stripped.split(), dtype=np.float64)
            if times is None:
                times = values
                continue
            rows.append(values)
    if params is None or times is None:
        raise UnreadableInputError(f"{path}: not an SHC file (no parameter or time line)")
    nmin, nmax, n_times, order, step = params
    if times.shape[0] != n_times:
        raise UnreadableInputError(
            f"{path}: expected {n_times} snapshot times, found {times.shape[0]}"
        )
    table = np.vstack(rows)
    if table.shape[1] != n_times + 2:
        raise UnreadableInputError(f"{path}: coefficient rows must hold n, m and {n_times} values")
    coeffs = np.zeros((n_times, nmax * (nmax + 2)))
    n = table[:, 0].astype(int)
    m = table[:, 1].astype(int)
    if n.min() < nmin or n.max() > nmax:
        raise UnreadableInputError(f"{path}: degrees outside {nmin}..{nmax}")
    # flat index: g_n0 -> n^2-1, g_nm -> n^2-1+2m-1, h_nm -> n^2-1+2m
    index = n * n - 1 + np.where(m > 0, 2 * m - 1, np.where(m < 0, -2 * m, 0))
    coeffs[:, index] = table[:, 2:].T
    return ShcFile(
        path=path,
        nmin=nmin,
        nmax=nmax,
        order=order,
        step=step,
        times_dyear=times,
        coeffs_flat=coeffs,
    )
