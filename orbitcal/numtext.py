"""Numbers written as text (URL query and path parameters, option values): one strict grammar.

Python's ``int()`` and ``float()`` read far more than a number written in ASCII: other scripts'
digits (``"١٢"`` is 12), ``_`` separators (``"1_000"``), surrounding whitespace, a leading
``+``; pydantic's lax integers add ``"1.0"``. A query ``start=١٢`` was read as Unix second 12
(issue 44). Here a number is

* an integer: ``-?[0-9]+`` (ASCII digits, an optional leading ``-``), at most
  :data:`MAX_DIGITS` digits;
* a real: an integer or ``-?[0-9]*.[0-9]+`` / ``-?[0-9]+.`` with an optional exponent
  ``[eE][+-]?[0-9]+``; no ``inf``/``nan``.

Nothing else (no whitespace, no ``+``, no ``_``, no other digits) is a number.
"""

from __future__ import annotations

import re

__all__ = ["INTEGER", "MAX_DIGITS", "REAL", "parse_integer_text", "parse_real_text"]

#: Longest integer text read [digits] (2^63 has 19; a bound against quadratic int() on 10^5).
MAX_DIGITS = 40
INTEGER = re.compile(r"-?[0-9]+", re.ASCII)
REAL = re.compile(r"-?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)

_INTEGER_RULE = "a decimal integer: ASCII digits 0-9 with an optional leading '-'"
_REAL_RULE = "a decimal number: ASCII digits 0-9, an optional leading '-', '.' and exponent"


def parse_integer_text(text: str) -> int:
    """``text`` as an integer, or ``ValueError`` saying the grammar."""
    if len(text) > MAX_DIGITS + 1 or not INTEGER.fullmatch(text):
        raise ValueError(f"{text[:40]!r} is not {_INTEGER_RULE}")
    return int(text)


def parse_real_text(text: str) -> float:
    """``text`` as a float, or ``ValueError`` saying the grammar."""
    if len(text) > 400 or not REAL.fullmatch(text):
        raise ValueError(f"{text[:40]!r} is not {_REAL_RULE}")
    return float(text)
