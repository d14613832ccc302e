"""Reference geomagnetic field models, evaluated per sample.

``get_field(name)`` returns a :class:`FieldModel`; names combine with ``+``:

============================  =====================================================
``IGRF-14``, ``IGRF-13``      IGRF generations (coefficients from ``ppigrf``)
``CHAOS-8.1``                 CHAOS-8.1 core field, n ≤ 20, time-dependent
``CHAOS-8.1-static``          CHAOS-8.1 lithospheric field, n = 21..185
``LCS-1``, ``MF7``            lithospheric models
``RC``                        magnetospheric ring-current field driven by the RC index
============================  =====================================================

e.g. ``"CHAOS-8.1+CHAOS-8.1-static+RC"`` or ``"IGRF-14+LCS-1"``. All models return geocentric
North, East, Centre (down) components [nT]; dates outside a model's validity raise
:class:`FieldRangeError`.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from orbitcal.errors import BadInputError
from orbitcal.field._base import (
    FieldModel,
    FieldRangeError,
    SphericalHarmonicModel,
    mjd2000_to_utc_s,
)
from orbitcal.field.chaos import chaos_core
from orbitcal.field.crust import CRUSTAL_MODELS, crustal_field
from orbitcal.field.external import RingCurrentField, ring_current_field
from orbitcal.field.igrf import IGRF_GENERATIONS, igrf

__all__ = [
    "DEFAULT_FIELD",
    "FIELD_NAMES",
    "MAIN_FIELD_NAMES",
    "CompositeField",
    "FieldModel",
    "FieldRangeError",
    "RingCurrentField",
    "SphericalHarmonicModel",
    "get_field",
    "reference_field_provenance",
]

#: The reference field when none is named (CONTRACT section 2).
DEFAULT_FIELD = "IGRF-14"

#: Core (main) field models: a combined name may hold at most one of them.
MAIN_FIELD_NAMES: tuple[str, ...] = (*IGRF_GENERATIONS, "CHAOS-8.1")

#: Every model name that ``get_field`` accepts as a term.
FIELD_NAMES: tuple[str, ...] = (*IGRF_GENERATIONS, "CHAOS-8.1", *CRUSTAL_MODELS, "RC")


class CompositeField:
    """Sum of several field models; its name joins theirs with ``+``."""

    def __init__(self, parts: tuple[FieldModel, ...]) -> None:
        if not parts:
            raise ValueError("a composite field needs at least one model")
        self.parts = parts

    @property
    def name(self) -> str:
        return "+".join(p.name for p in self.parts)

    def b_nec_nt(
        self,
        t_utc_s: NDArray[np.float64],
        radius_km: NDArray[np.float64],
        colat_deg: NDArray[np.float64],
        lon_deg: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Sum of the parts' fields, geocentric NEC [nT] (see :class:`FieldModel`)."""
        total = self.parts[0].b_nec_nt(t_utc_s, radius_km, colat_deg, lon_deg)
        for part in self.parts[1:]:
            total = total + part.b_nec_nt(t_utc_s, radius_km, colat_deg, lon_deg)
        return total

    def __repr__(self) -> str:
        return f"CompositeField({self.name!r})"


def _single(name: str) -> FieldModel:
    if name in IGRF_GENERATIONS:
        return igrf(name)
    if name == "CHAOS-8.1":
        return chaos_core(name)
    if name in CRUSTAL_MODELS:
        return crustal_field(name)
    if name == "RC":
        return ring_current_field()
    hint = ""
    if name.upper() == "IGRF":
        hint = " (name the generation, e.g. IGRF-14)"
    raise BadInputError(f"unknown field model {name!r}{hint}; available: {', '.join(FIELD_NAMES)}")


@lru_cache(maxsize=32)
def get_field(name: str = DEFAULT_FIELD) -> FieldModel:
    """The field model called ``name``; terms combine with ``+`` (e.g. ``"CHAOS-8.1+LCS-1+RC"``).

    Parameters
    ----------
    name : str
        Model name(s); spaces around ``+`` are ignored, case matters.

    Returns
    -------
    FieldModel
        Loaded once per name and cached; ``.name`` is the full canonical name.

    Raises
    ------
    ValueError
        For an unknown or repeated term.
    """
    terms = tuple(t.strip() for t in name.split("+"))
    if any(not t for t in terms):
        raise BadInputError(f"empty term in field name {name!r}")
    if len(set(terms)) != len(terms):
        raise BadInputError(f"field name {name!r} repeats a term")
    main = [t for t in terms if t in MAIN_FIELD_NAMES]
    if len(main) > 1:
        raise BadInputError(
            f"field name {name!r} adds {' and '.join(main)}: both are main-field models; use one"
        )
    if len(terms) == 1:
        return _single(terms[0])
    return CompositeField(tuple(_single(t) for t in terms))


def reference_field_provenance(name: str) -> dict[str, Any]:
    """The reference field model(s) a result used: name, model family, generation, validity end.

    Returns
    -------
    dict
        ``{"name": name, "models": [{"name", "model", "generation", "valid_until"?}, ...]}``, one
        entry per ``+`` term; ``valid_until`` (ISO UTC) for a model with a validity span, ``None``
        for a term :func:`get_field` refuses. :func:`orbitcal.provenance.result_provenance` adds
        it to the tables' block.
    """
    models = []
    for term in (t.strip() for t in str(name).split("+")):
        m = re.fullmatch(r"([A-Za-z]+)-(\d+(?:\.\d+)?)(-static)?", term)
        entry: dict[str, Any] = {
            "name": term,
            "model": m.group(1) if m else term,
            "generation": m.group(2) if m else None,
        }
        try:
            valid = getattr(get_field(term), "valid_mjd2000", None)
            if valid is not None:
                t_end_utc_s = float(mjd2000_to_utc_s(np.asarray(float(valid[1]))))
                entry["valid_until"] = datetime.fromtimestamp(t_end_utc_s, tz=UTC).strftime(
                    "%Y-%m-%dT%H:%M:%SZ"
                )
        except ValueError:
            entry["valid_until"] = None
        models.append(entry)
    return {"name": str(name), "models": models}
