"""Integer query and path parameters in one strict grammar, with bounds (issue 44).

FastAPI reads an ``int`` parameter through pydantic's lax mode, which takes ``"+1"``, ``" 1"``,
``"1_0"`` (as 10) and ``"1.0"``; a version past 64 bits reached the database and was a 500.
Every integer parameter of the routes is annotated with :data:`ASCII_INTEGER` (the grammar of
:mod:`orbitcal.numtext`: ASCII digits, an optional leading ``-``) and bounds; past them the
answer is 422 naming the parameter. Times given as numbers (``start``, ``end``) go through
:func:`orbitcal.timescales.parse_instant_utc_s`, which uses the same grammar.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Path
from pydantic import BeforeValidator

from orbitcal.numtext import parse_integer_text

__all__ = ["ASCII_INTEGER", "VERSION_MAX", "VersionPath"]

#: The largest calibration version a path may name (the column is a signed 64-bit integer).
VERSION_MAX = 2**63 - 1


def _integer(value: object) -> object:
    return parse_integer_text(value) if isinstance(value, str) else value


#: Put last in the ``Annotated[int, Query(...), ...]`` of every integer query or path parameter.
ASCII_INTEGER = BeforeValidator(_integer)

VersionPath = Annotated[
    int,
    Path(ge=1, le=VERSION_MAX, description="a calibration version, 1 .. 2^63 - 1"),
    ASCII_INTEGER,  # after Path: the OpenAPI schema keeps minimum/maximum
]
