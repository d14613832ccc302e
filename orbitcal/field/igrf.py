"""IGRF (International Geomagnetic Reference Field), generations 13 and 14.

The coefficient files are the official .shc files as shipped inside the ``ppigrf`` wheel
(``ppigrf/IGRF14.shc``, ``ppigrf/IGRF13.shc``), read once. IGRF is defined piecewise linear in time
between its 5-year epochs, the last interval carrying the predictive secular variation
(Alken et al. 2021, "International Geomagnetic Reference Field: the thirteenth generation", EPS
73:49, sec. 2; IGRF-14: IAGA V-MOD 2024, doi:10.5281/zenodo.14012302). Epochs are the instants
``YYYY-01-01T00:00Z`` and coefficients are interpolated linearly in UTC time between them — the same
convention as ``ppigrf`` (pandas ``interpolate(method='time')``), so interpolation is exact.
"""

from __future__ import annotations

import datetime as _dt
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from orbitcal.errors import BadInputError
from orbitcal.field._base import SphericalHarmonicModel
from orbitcal.field.shc import read_shc

__all__ = ["IGRF_GENERATIONS", "igrf", "igrf_shc_path"]

#: Generations available, by the name used in outputs.
IGRF_GENERATIONS: dict[str, str] = {"IGRF-14": "IGRF14.shc", "IGRF-13": "IGRF13.shc"}


def igrf_shc_path(name: str) -> Path:
    """Path of the .shc file of an IGRF generation (inside the installed ppigrf package)."""
    try:
        filename = IGRF_GENERATIONS[name]
    except KeyError:
        raise BadInputError(
            f"unknown IGRF generation {name!r}; available: {', '.join(IGRF_GENERATIONS)}"
        ) from None
    return Path(str(resources.files("ppigrf").joinpath(filename)))


def _year_start_mjd2000(year: float) -> float:
    if year != int(year):
        raise ValueError(f"IGRF epoch {year} is not a whole year")
    delta = _dt.datetime(int(year), 1, 1) - _dt.datetime(2000, 1, 1)
    return delta.total_seconds() / 86_400.0


@lru_cache(maxsize=4)
def igrf(name: str = "IGRF-14") -> SphericalHarmonicModel:
    """The IGRF generation ``name`` (``"IGRF-14"`` or ``"IGRF-13"``), loaded once.

    Valid from 1900-01-01 to the end of its predictive interval (2030-01-01 for IGRF-14,
    2025-01-01 for IGRF-13).
    """
    shc = read_shc(igrf_shc_path(name))
    if shc.order != 2:
        raise ValueError(f"{name}: expected a piecewise-linear .shc (order 2), got {shc.order}")
    breaks = np.array([_year_start_mjd2000(y) for y in shc.times_dyear])
    coeffs = shc.coeffs_flat  # (N, K)
    slope_per_day = np.diff(coeffs, axis=0) / np.diff(breaks)[:, None]
    coeffs_pp = np.stack([slope_per_day, coeffs[:-1]])  # (2, P, K)
    return SphericalHarmonicModel(
        name, nmin=shc.nmin, nmax=shc.nmax, breaks_mjd2000=breaks, coeffs_pp_flat=coeffs_pp
    )
