"""The one tree of orbitcal's errors, split by what the caller can do about them.

Every error the library raises on purpose derives from :class:`OrbitcalError`. The subclasses say
what to do next, so the CLI maps them to exit codes in one place and the service maps them to HTTP
statuses in one place, without catching built-in exception types:

=========================  ==============================================  =====  ====
class                      what the caller can do                          exit   HTTP
=========================  ==============================================  =====  ====
``BadInputError``          fix the named row/field of the input              2     422
``UnreadableInputError``   send the input in the declared format/encoding    2     400
``LimitExceededError``     send less (a documented limit was exceeded)       2     413
``OutOfRangeError``        use another model or drop the samples             2     422
``NotEnoughDataError``     collect more data (or more varied data)           3     422
``OrbitProblemError``      supply a better TLE/OMM or positions              2     422
``StaleDataError``         update the auxiliary tables (``data update``)     4     503
``ConflictError``          wait for the running operation                    5     409
=========================  ==============================================  =====  ====

Every class also derives from ``ValueError`` so code written before the tree existed keeps working;
new code catches :class:`OrbitcalError` or a subclass. :func:`reading_untrusted_input` is the one
last resort for readers of untrusted bytes (see its docstring for when it may be used).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = [
    "BadInputError",
    "ConflictError",
    "LimitExceededError",
    "NotEnoughDataError",
    "OrbitProblemError",
    "OrbitcalError",
    "OutOfRangeError",
    "StaleDataError",
    "UnreadableInputError",
    "reading_untrusted_input",
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


class UnreadableInputError(BadInputError):
    """The input as a whole cannot be read: not the declared format, encoding or compression.

    Nothing of it was used; send it again as what it claims to be (HTTP 400, a malformed request,
    where :class:`BadInputError` is a readable input with wrong values, 422).
    """

    http_status = 400


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


#: The built-in exceptions a third-party reader (pandas, pyarrow, orjson, zlib, struct) may raise on
#: hostile bytes that no check before it foresaw.
_READER_FAILURES: tuple[type[Exception], ...] = (
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    OverflowError,
)


@contextmanager
def reading_untrusted_input(
    what: str, *, field: str | None = None, error: type[BadInputError] = UnreadableInputError
) -> Iterator[None]:
    """Last resort around a reader of untrusted bytes: an unforeseen failure becomes ``error``.

    Only for code that hands bytes a user controls to third-party parsers, whose exceptions on
    hostile input are not documented and cannot all be foreseen by checks before them: the user
    gets a clear "could not be read" naming ``what`` (and ``field``) instead of a crash or an
    HTTP 500, and the failure is logged with its traceback as a reader bug to fix. Errors of the
    tree pass through unchanged. Anywhere else raise the typed error where the problem is found.

    Parameters
    ----------
    what : str
        The input, as the message names it (e.g. ``"csv body"``).
    field : str, optional
        The field, option or header to name in the error.
    error : type of BadInputError
        The class to raise (default :class:`UnreadableInputError`).
    """
    try:
        yield
    except OrbitcalError:
        raise
    except _READER_FAILURES as exc:
        logging.getLogger("orbitcal.readers").error("%s could not be read", what, exc_info=exc)
        message = f"the {what} could not be read ({type(exc).__name__}: {exc})"[:500]
        raise error(message, field=field) from None
