"""The provenance block every result carries: the auxiliary tables and the reference field model.

It joins :func:`orbitcal.auxdata.tables_provenance` (leap seconds, EOP, RC index) and
:func:`orbitcal.field.reference_field_provenance` (model generation, validity end). It lives above
both packages so that the dependency runs one way: ``orbitcal.field`` reads the RC index from
``orbitcal.auxdata``; ``orbitcal.auxdata`` never asks ``orbitcal.field``.
"""

from __future__ import annotations

from typing import Any

import numpy.typing as npt

__all__ = ["result_provenance"]


def result_provenance(
    t_utc_s: npt.ArrayLike,
    *,
    reference_field: str | None = None,
    kinds: tuple[str, ...] = ("leap_seconds", "eop", "rc_index"),
    rc_index_used: bool | None = None,
    external_field_variant: str | None = None,
) -> dict[str, Any]:
    """The provenance block of a result over the sample times ``t_utc_s``.

    Parameters
    ----------
    t_utc_s : array_like, shape (n,)
        Sample times [s, POSIX UTC]; non-finite ones are ignored.
    reference_field : str, optional
        The reference field name (e.g. ``"IGRF-14"``); adds a ``reference_field`` block.
    kinds, rc_index_used, external_field_variant
        As :func:`orbitcal.auxdata.tables_provenance`.

    Returns
    -------
    dict
        ``{"span", "tables", "warnings"}`` from the tables, plus ``"reference_field"`` when one
        is named.
    """
    from orbitcal.auxdata import tables_provenance
    from orbitcal.field import reference_field_provenance

    out = tables_provenance(
        t_utc_s,
        kinds=kinds,
        rc_index_used=rc_index_used,
        external_field_variant=external_field_variant,
    )
    if reference_field is not None:
        out["reference_field"] = reference_field_provenance(reference_field)
    return out
