"""The exports' error (its own module so that the name policy and the options share it)."""

from __future__ import annotations

from orbitcal.errors import BadInputError

__all__ = ["ExportError"]


class ExportError(BadInputError):
    """An export cannot be made as asked (bad option, names, target answer); names the field."""
