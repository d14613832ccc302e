"""Static lithospheric (crustal) field models shipped with orbitcal.

- ``CHAOS-8.1-static``: CHAOS-8.1 lithospheric part, n = 21..185 (DTU Space; Finlay et al. 2020).
- ``LCS-1``: Olsen, Ravat, Finlay & Kother (2017), "LCS-1: a high-resolution global model of the
  lithospheric magnetic field derived from CHAMP and Swarm satellite observations", GJI 211(3),
  1461–1477; n = 1..185.
- ``MF7``: Maus (2010) and co-workers, NGDC/CIRES MF7, n = 16..133.

Evaluation cost grows as nmax²: about 100× a degree-13 IGRF per point at n = 185.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from orbitcal.errors import BadInputError
from orbitcal.field._base import SphericalHarmonicModel
from orbitcal.field.chaos import field_data_path
from orbitcal.field.shc import read_shc

__all__ = ["CRUSTAL_MODELS", "crustal_field", "crustal_field_above"]

#: Crustal model names and their .shc files in ``orbitcal/field/data/``.
CRUSTAL_MODELS: dict[str, str] = {
    "CHAOS-8.1-static": "CHAOS-8.1_static.shc",
    "LCS-1": "LCS-1.shc",
    "MF7": "MF7.shc",
}


@lru_cache(maxsize=4)
def crustal_field(name: str) -> SphericalHarmonicModel:
    """A static crustal model by name (see :data:`CRUSTAL_MODELS`), loaded once."""
    try:
        filename = CRUSTAL_MODELS[name]
    except KeyError:
        raise BadInputError(
            f"unknown crustal model {name!r}; available: {', '.join(CRUSTAL_MODELS)}"
        ) from None
    shc = read_shc(field_data_path(filename))
    if shc.coeffs_flat.shape[0] != 1:
        raise ValueError(f"{name}: expected a single static snapshot")
    return SphericalHarmonicModel(
        name,
        nmin=shc.nmin,
        nmax=shc.nmax,
        breaks_mjd2000=np.array([0.0, 0.0]),
        coeffs_pp_flat=shc.coeffs_flat[None, :, :],
        static=True,
    )


@lru_cache(maxsize=8)
def crustal_field_above(name: str, nmin: int, nmax: int | None = None) -> SphericalHarmonicModel:
    """The crustal model ``name`` from degree ``nmin`` on (its own lowest degree if higher), up to
    degree ``nmax`` (its own highest by default).

    A main-field model of degree ``N`` (IGRF: 13, CHAOS core: 20) is fitted to the whole internal
    field up to ``N``, the lithosphere's long wavelengths included: what a crustal model adds to
    it is its part above ``N``. LCS-1 starts at degree 1; its degrees 1..13 (0.7 nT rms at 460 km
    of its 2.1) are already in IGRF.
    """
    model = crustal_field(name)
    top = model.nmax if nmax is None else min(int(nmax), model.nmax)
    if nmin <= model.nmin and top == model.nmax:
        return model
    low = max(nmin, model.nmin)
    return SphericalHarmonicModel(
        f"{name} (n >= {low})" if top == model.nmax else f"{name} (n = {low}..{top})",
        nmin=low,
        nmax=top,
        breaks_mjd2000=model.breaks_mjd2000,
        coeffs_pp_flat=model.coeffs_pp_flat[:, :, : top * (top + 2)],
        static=True,
    )
