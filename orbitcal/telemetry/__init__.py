"""The contract's telemetry table (CONTRACT section 1): readers, writers and row-level validation.

One row per magnetometer sample, the same columns in CSV, Parquet, NDJSON and a JSON array of
objects. Inside the library a table is a :class:`Telemetry` of columnar arrays (``docs/design.md``):

========================  ==========  ======================================================
column(s)                 attribute   meaning
========================  ==========  ======================================================
``time``                  t_utc_s     POSIX seconds of UTC [s], shape (N,)
``b_x, b_y, b_z``         b_raw_nt    raw magnetometer output, sensor axes [nT], shape (N, 3)
``q_w, q_x, q_y, q_z``    q_wxyz      body orientation in the attitude frame, shape (N, 4)
``r_x, r_y, r_z``         r_itrs_km   position, ITRS [km], shape (N, 3)
``temperature``           temperature_c  sensor temperature [°C], shape (N,)
``mtq_x, mtq_y, mtq_z``   mtq_am2     magnetorquer dipole commands [A·m²], shape (N, 3)
``hk_<name>``             hk          other housekeeping, keyed by the full column name
========================  ==========  ======================================================

Validation happens once, here, at the edge (STYLE rule 10). Readers return a :class:`ReadResult`:
the valid rows plus one :class:`RowError` per rejected row (0-based data row of the upload, the
reason naming the field). Rules:

* a missing required column (``time``, ``b_x``, ``b_y``, ``b_z``) or a partial group of optional
  columns (e.g. ``q_w, q_x, q_y`` without ``q_z``) fails the whole table with
  :class:`TelemetryError` naming the column;
* a row is rejected for: an unreadable time, a non-finite number in any numeric column,
  an absurd field (``|b| > 1e6 nT``), a quaternion whose norm is off 1 by more than 1e-3, a
  position inside the Earth or beyond 10^6 km, a temperature below absolute zero, a partly filled
  quaternion or position, or a time equal to that of an earlier row (the first one is kept);
* unknown columns are ignored with a warning;
* rows are **sorted by time** (stable), not rejected, when they arrive out of order; row numbers
  in errors always refer to the upload's order.

Times are ISO-8601 with a zone (``Z``) or numbers of Unix seconds, read in the time scale the
caller declares (``UTC``, ``TAI`` or ``GPS``, never guessed) and converted to UTC with the
leap-second table of :mod:`orbitcal.timescales`. Writers always write UTC, ISO-8601 with ``Z`` and
microseconds.

Everything is columnar (pandas/pyarrow, NDJSON through orjson): no per-row Python objects are
built for valid CSV or Parquet data.
"""

from orbitcal.telemetry.limits import DEFAULT_LIMITS, ParseLimits, json_scan
from orbitcal.telemetry.readers import from_frame, parse_telemetry, read_telemetry
from orbitcal.telemetry.table import (
    B_ABSURD_NT,
    OPTIONAL_GROUPS,
    QUAT_NORM_TOL,
    REQUIRED_COLUMNS,
    ReadResult,
    RowError,
    Telemetry,
    TelemetryError,
    TelemetryFormat,
    format_from_path,
)
from orbitcal.telemetry.writers import write_field_csv, write_telemetry

__all__ = [
    "B_ABSURD_NT",
    "DEFAULT_LIMITS",
    "OPTIONAL_GROUPS",
    "QUAT_NORM_TOL",
    "REQUIRED_COLUMNS",
    "ParseLimits",
    "ReadResult",
    "RowError",
    "Telemetry",
    "TelemetryError",
    "TelemetryFormat",
    "format_from_path",
    "from_frame",
    "json_scan",
    "parse_telemetry",
    "read_telemetry",
    "write_field_csv",
    "write_telemetry",
]
