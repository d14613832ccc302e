"""The one tree of orbitcal's errors, split by what the caller can do about them.

Every error the library raises on purpose derives from :class:`OrbitcalError`. The subclasses say
what to do next, so the CLI maps them to exit codes in one place and the service maps them to HTTP
statuses in one place, without catching built-in exception types:

=========================  ==============================================  =====  ====
class                      what the caller can do                          exit   HTTP
=========================  ==============================================  =====  ====
``BadInputError``          fix the named row/field of the input              2     422
``LimitExceededError``     send less (a documented limit was exceeded)       2     413
``OutOfRangeError``        use another model or drop the samples             2     422
``NotEnoughDataError``     collect more data (or more varied data)           3     422
``OrbitProblemError``      supply a better TLE/OMM or positions              2     422
``StaleDataError``         update the auxiliary tables (``data update``)     4     503
``ConflictError``          wait for the running operation                    5     409
=========================  ==============================================  =====  ====

Every class also derives from ``ValueError`` so code written before the tree existed keeps working;
new code catches :class:`OrbitcalError` or a subclass.
"""

from __future__ import annotations

__all__ = [
    "BadInputError",
    "ConflictError",
    "LimitExceededError",
    "NotEnoughDataError",
    "OrbitProblemError",
    "OrbitcalError",
    "OutOfRangeError",
    "StaleDataError",
]


class OrbitcalError(ValueError):
    """Base class of every error orbitcal raises on purpose.

    Attributes
    ----------
    exit_code : int
        The CLI's exit status for this class of error (CONTRACT section 2: non-zero).
    http_status : int
        The service's HTTP status for this class of error.
    """

    exit_code: int = 2
    http_status: int = 422


class BadInputError(OrbitcalError):
    """The input is malformed; the message names the row and/or field and the reason.

    Parameters
    ----------
    message : str
        The reason, in words a user can act on.
    row : int or None
        0-based row of the input, when one row is at fault.
    field : str or None
        The column, key or option at fault.
    """

    def __init__(self, message: str, *, row: int | None = None, field: str | None = None) -> None:
        self.row = row
        self.field = field
        super().__init__(message)


class LimitExceededError(BadInputError):
    """A documented size limit (bytes, rows, columns, depth, string length) was exceeded."""

    http_status = 413

    def __init__(self, message: str, *, limit_name: str, limit: int | float) -> None:
        self.limit_name = limit_name
        self.limit = limit
        super().__init__(message, field=limit_name)


class OutOfRangeError(OrbitcalError):
    """A value lies outside the validity of a model (a field model's dates, a table's coverage)."""


class NotEnoughDataError(OrbitcalError):
    """Too few samples, or samples too alike, for what was asked; collect more data."""

    exit_code = 3


class OrbitProblemError(OrbitcalError):
    """The orbit cannot be used: malformed, unphysical, decayed or stale elements."""


class StaleDataError(OrbitcalError):
    """An auxiliary table (leap seconds, EOP, space weather) does not cover the data."""

    exit_code = 4
    http_status = 503


class ConflictError(OrbitcalError):
    """The operation conflicts with one already running; wait for it or cancel it."""

    exit_code = 5
    http_status = 409
