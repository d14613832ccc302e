"""The ingest readers' error: a ``BadInputError`` naming the file, the line and the field."""

from __future__ import annotations

from pathlib import Path

from orbitcal.errors import BadInputError

__all__ = ["IngestError"]


class IngestError(BadInputError):
    """A mission file cannot be read as the product it claims to be.

    The message starts with ``FILE[:LINE]`` and names the field (header variable, CDF variable or
    column) and the reason, so that a user can open the file at the right place.

    Parameters
    ----------
    path : str or Path
        The file at fault.
    message : str
        The reason.
    line : int or None
        1-based line of a text file (header lines included), when one line is at fault.
    field : str or None
        The variable or column at fault.
    """

    def __init__(
        self,
        path: str | Path,
        message: str,
        *,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.path = str(path)
        self.line = line
        where = f"{self.path}:{line}" if line is not None else self.path
        what = f" (field {field})" if field else ""
        super().__init__(f"{where}: {message}{what}", row=None, field=field)
