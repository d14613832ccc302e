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

from __future__ import annotations

import csv
import io
import json
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import numpy.typing as npt
import orjson
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from orbitcal.arrays import FloatArray
from orbitcal.errors import LimitExceededError, UnreadableInputError, reading_untrusted_input
from orbitcal.timescales import (
    TIME_SCALES,
    TimeScaleError,
    from_utc_s,
    parse_time_values,
    to_utc_s,
)

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

TelemetryFormat = Literal["csv", "ndjson", "json", "parquet"]

#: Columns every table must carry (CONTRACT section 1).
REQUIRED_COLUMNS: tuple[str, ...] = ("time", "b_x", "b_y", "b_z")
#: Optional column groups: all columns of a group or none.
OPTIONAL_GROUPS: dict[str, tuple[str, ...]] = {
    "quaternion": ("q_w", "q_x", "q_y", "q_z"),
    "position": ("r_x", "r_y", "r_z"),
    "temperature": ("temperature",),
    "magnetorquer": ("mtq_x", "mtq_y", "mtq_z"),
}
#: A field magnitude above this is not a magnetometer reading [nT] (Earth's surface field < 7e4 nT).
B_ABSURD_NT = 1e6
#: Largest accepted deviation of |q| from 1 (CONTRACT section 1).
QUAT_NORM_TOL = 1e-3
#: Accepted geocentric distance of a position [km]: above the Earth's surface, below 10^6 km.
R_MIN_KM = 6300.0
R_MAX_KM = 1e6
#: Accepted sample times: 1900-01-01 … 2200-01-01 [POSIX s].
T_MIN_S = -2_208_988_800.0
T_MAX_S = 7_258_118_400.0
HK_PREFIX = "hk_"


@dataclass(frozen=True)
class ParseLimits:
    """Size limits every reader enforces before a native parser (orjson, pyarrow, pandas) runs.

    A table beyond a limit raises :class:`~orbitcal.errors.LimitExceededError` (HTTP 413) naming
    the limit; the limits are documented in ``docs/reliability.md``. Bytes are bounded before
    this point (the service's body limit applies to the *decompressed* body).

    Attributes
    ----------
    max_rows : int
        Data rows (CSV lines, NDJSON lines, JSON elements, Parquet rows from the file's metadata,
        CCSDS packets).
    max_columns : int
        Columns of a table (contract columns plus ``hk_*`` channels and ignored ones).
    max_cells : int
        Rows × columns after expansion (Parquet from its metadata; JSON: values in the body).
    max_json_depth : int
        Nesting depth of ``[`` / ``{`` in JSON and in each NDJSON line (a record is depth 1).
    max_name_chars : int
        Length of a column name [characters].
    max_string_chars : int
        Length of one text cell (times, text housekeeping) [characters].
    max_decoded_bytes : int
        Parquet: uncompressed size of the column data, from the file's metadata [bytes].
    """

    max_rows: int = 1_000_000
    max_columns: int = 256
    max_cells: int = 16_000_000
    max_json_depth: int = 8
    max_name_chars: int = 128
    max_string_chars: int = 4096
    max_decoded_bytes: int = 512 * 2**20


#: The limits the readers and the service use unless told otherwise.
DEFAULT_LIMITS = ParseLimits()


def _limit(what: str, value: int | float, name: str, limit: int | float) -> LimitExceededError:
    return LimitExceededError(
        f"{what} ({value:,}) exceeds the limit {name} = {limit:,}", limit_name=name, limit=limit
    )


_SCAN_CHUNK = 1 << 20
#: Bytes the JSON scan looks at: " \\ [ { ] } line ends (LF, CR), comma and colon.
_SCAN_EVENTS = np.zeros(256, dtype=bool)
_SCAN_EVENTS[[34, 92, 91, 123, 93, 125, 10, 13, 44, 58]] = True


def json_scan(data: bytes, *, per_line: bool) -> tuple[int, int, int, int]:
    """Structure of a JSON (or NDJSON) body without parsing it.

    Returns ``(max_depth, at_byte, commas, colons)``.

    A vectorised pass over the raw bytes (1 MiB at a time, only the structural bytes kept):
    quotes not escaped by an odd run of backslashes toggle "inside a string" (reset at each
    line end, LF or CR, where no valid JSON string can continue); ``[``/``{`` and ``]``/``}``
    outside strings move the depth. For NDJSON (``per_line``) the depth counts from each line's
    start. Up to the first syntax error a parser would stop at, this is the parser's own view,
    so a body that passes a depth check here cannot drive a parser deeper. ``commas`` (outside
    strings) bounds the number of values; ``colons`` (outside strings) is the number of object
    keys, so a parser that keeps fewer keys dropped a repeated one.
    """
    a_all = np.frombuffer(data, dtype=np.uint8)
    depth = 0  # depth at the end of the previous chunk
    line_base = 0  # depth at the start of the current line (NDJSON)
    quotes_open = 0  # 1 when the previous chunk ended inside a string
    bs_run = 0  # backslashes ending the previous chunk
    best, best_at, commas, colons = 0, 0, 0, 0
    for start in range(0, a_all.size, _SCAN_CHUNK):
        chunk = a_all[start : start + _SCAN_CHUNK]
        pos = np.flatnonzero(_SCAN_EVENTS[chunk])
        if pos.size == 0:
            bs_run = 0
            continue
        c = chunk[pos]
        e = np.arange(pos.size)
        is_bs = c == 92
        escaped = np.zeros(pos.size, dtype=bool)
        if bs_run or is_bs.any():
            adj = np.empty(pos.size, dtype=bool)
            adj[0] = pos[0] == 0
            adj[1:] = np.diff(pos) == 1
            prev_bs = np.empty(pos.size, dtype=bool)
            prev_bs[0] = bs_run > 0
            prev_bs[1:] = is_bs[:-1]
            cont = is_bs & prev_bs & adj
            run_start = np.maximum.accumulate(np.where(is_bs & ~cont, e, -1))
            run = np.where(is_bs, np.where(run_start >= 0, e - run_start + 1, e + 1 + bs_run), 0)
            prev_run = np.empty(pos.size, dtype=np.int64)
            prev_run[0] = bs_run
            prev_run[1:] = run[:-1]
            escaped = prev_bs & adj & (prev_run % 2 == 1)
            bs_run = int(run[-1]) if is_bs[-1] and pos[-1] == chunk.size - 1 else 0
        else:
            bs_run = 0
        quote = (c == 34) & ~escaped
        line_start = np.maximum.accumulate(np.where((c == 10) | (c == 13), e, -1))
        has_start = line_start >= 0
        ls = np.maximum(line_start, 0)
        qcum = np.cumsum(quote, dtype=np.int64) + quotes_open
        qbase = np.where(has_start, qcum[ls], 0)
        outside = ((qcum - qbase) & 1) == 0
        step = ((c == 91) | (c == 123)).astype(np.int64) - ((c == 93) | (c == 125))
        d = np.cumsum(np.where(outside, step, 0)) + depth
        rel = d - np.where(has_start, d[ls], line_base) if per_line else d
        k = int(np.argmax(rel))
        if int(rel[k]) > best:
            best, best_at = int(rel[k]), start + int(pos[k])
        commas += int(np.count_nonzero((c == 44) & outside))
        colons += int(np.count_nonzero((c == 58) & outside))
        depth = int(d[-1])
        if per_line and has_start[-1]:
            line_base = int(d[ls[-1]])
        quotes_open = int((qcum[-1] - qbase[-1]) & 1)
    return best, best_at, commas, colons


def _check_json_structure(data: bytes, *, per_line: bool, limits: ParseLimits) -> tuple[int, int]:
    """Depth and value count of a JSON body within the limits; returns (keys, max depth)."""
    depth, at, commas, colons = json_scan(data, per_line=per_line)
    if depth > limits.max_json_depth:
        line = data.count(b"\n", 0, at)
        raise LimitExceededError(
            f"JSON nested {depth:,} deep at line {line + 1} (byte {at}) exceeds the limit "
            f"max_json_depth = {limits.max_json_depth} (a sample is one flat object)",
            limit_name="max_json_depth",
            limit=limits.max_json_depth,
        )
    if commas + 1 > limits.max_cells:
        raise _limit("values in the JSON body", commas + 1, "max_cells", limits.max_cells)
    return colons, depth


_EXTENSIONS: dict[str, TelemetryFormat] = {
    ".csv": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".ndjson": "ndjson",
    ".jsonl": "ndjson",
    ".json": "json",
}
_KNOWN_COLUMNS = frozenset(REQUIRED_COLUMNS).union(*OPTIONAL_GROUPS.values())


class TelemetryError(UnreadableInputError):
    """The table as a whole cannot be read (missing column, bad format, unknown time scale).

    Fix the file or the option named in the message; row-level problems never raise, they are
    returned as :class:`RowError` entries. HTTP 400 (a malformed upload), exit code 2.
    """


class RowError(NamedTuple):
    """One rejected data row: 0-based row number in the upload's order and the reason."""

    row: int
    reason: str


@dataclass(frozen=True, eq=False)
class Telemetry:
    """A validated telemetry table (columnar, sorted by time, unique times).

    Attributes
    ----------
    t_utc_s : ndarray, shape (N,)
        Sample times, POSIX seconds of UTC [s].
    b_raw_nt : ndarray, shape (N, 3)
        Raw magnetometer output in sensor axes [nT].
    q_wxyz : ndarray, shape (N, 4), or None
        Body orientation in the attitude frame (GCRS by default), scalar first:
        ``v_body = Rotation.from_quat([x, y, z, w]).inv().apply(v_frame)``.
    r_itrs_km : ndarray, shape (N, 3), or None
        Position in ITRS [km].
    temperature_c : ndarray, shape (N,), or None
        Sensor temperature [°C].
    mtq_am2 : ndarray, shape (N, 3), or None
        Magnetorquer dipole commands, body axes [A·m²].
    hk : dict of str to ndarray, shape (N,)
        Other housekeeping channels keyed by their full column name (``"hk_<name>"``); numeric
        channels are float64, others object arrays of str.
    """

    t_utc_s: FloatArray
    b_raw_nt: FloatArray
    q_wxyz: FloatArray | None = None
    r_itrs_km: FloatArray | None = None
    temperature_c: FloatArray | None = None
    mtq_am2: FloatArray | None = None
    hk: dict[str, npt.NDArray[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = np.shape(self.t_utc_s)[0] if np.ndim(self.t_utc_s) == 1 else -1
        if n < 0:
            raise ValueError("t_utc_s must have shape (N,)")
        shapes: dict[str, tuple[npt.NDArray[Any] | None, tuple[int, ...]]] = {
            "b_raw_nt": (self.b_raw_nt, (n, 3)),
            "q_wxyz": (self.q_wxyz, (n, 4)),
            "r_itrs_km": (self.r_itrs_km, (n, 3)),
            "temperature_c": (self.temperature_c, (n,)),
            "mtq_am2": (self.mtq_am2, (n, 3)),
        }
        for name, (arr, shape) in shapes.items():
            if arr is not None and np.shape(arr) != shape:
                raise ValueError(f"{name} has shape {np.shape(arr)}, expected {shape}")
        for name, arr in self.hk.items():
            if not name.startswith(HK_PREFIX):
                raise ValueError(f"housekeeping channel {name!r} must be named 'hk_<name>'")
            if np.shape(arr) != (n,):
                raise ValueError(f"{name} has shape {np.shape(arr)}, expected {(n,)}")

    def __len__(self) -> int:
        return int(self.t_utc_s.shape[0])

    def select(self, mask_or_index: npt.ArrayLike | slice) -> Telemetry:
        """The rows picked by a boolean mask, an integer index array or a slice (a new table)."""
        idx: Any = mask_or_index if isinstance(mask_or_index, slice) else np.asarray(mask_or_index)

        def pick(a: npt.NDArray[Any] | None) -> Any:
            return None if a is None else a[idx]

        return Telemetry(
            t_utc_s=self.t_utc_s[idx],
            b_raw_nt=self.b_raw_nt[idx],
            q_wxyz=pick(self.q_wxyz),
            r_itrs_km=pick(self.r_itrs_km),
            temperature_c=pick(self.temperature_c),
            mtq_am2=pick(self.mtq_am2),
            hk={k: v[idx] for k, v in self.hk.items()},
        )

    def sort_by_time(self) -> Telemetry:
        """The rows in ascending time (stable); ``self`` when already sorted."""
        if len(self) < 2 or bool(np.all(np.diff(self.t_utc_s) >= 0)):
            return self
        return self.select(np.argsort(self.t_utc_s, kind="stable"))

    def regressors(self) -> tuple[FloatArray, list[str]]:
        """Housekeeping regressors for the calibrators and the diagnosis.

        Returns
        -------
        x_hk : ndarray, shape (N, k)
            Columns in the order of ``names``: temperature [°C], ``mtq_x, mtq_y, mtq_z`` [A·m²],
            then every numeric ``hk_*`` channel (sorted by name) in its own unit.
        names : list of str
            Column names as in the table (``"temperature"``, ``"mtq_x"``, …, ``"hk_<name>"``).
        """
        cols: list[FloatArray] = []
        names: list[str] = []
        if self.temperature_c is not None:
            cols.append(np.asarray(self.temperature_c, dtype=np.float64))
            names.append("temperature")
        if self.mtq_am2 is not None:
            for j, axis in enumerate("xyz"):
                cols.append(np.asarray(self.mtq_am2[:, j], dtype=np.float64))
                names.append(f"mtq_{axis}")
        for name in sorted(self.hk):
            arr = self.hk[name]
            if arr.dtype.kind in "iufb":
                cols.append(arr.astype(np.float64))
                names.append(name)
        x_hk = np.column_stack(cols) if cols else np.empty((len(self), 0))
        return x_hk, names

    def to_frame(self) -> pd.DataFrame:
        """The table with the contract's columns (``time`` as ISO-8601 UTC with ``Z``)."""
        data: dict[str, Any] = {"time": _iso_z(self.t_utc_s)}
        for j, c in enumerate(("b_x", "b_y", "b_z")):
            data[c] = self.b_raw_nt[:, j]
        if self.q_wxyz is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["quaternion"]):
                data[c] = self.q_wxyz[:, j]
        if self.r_itrs_km is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["position"]):
                data[c] = self.r_itrs_km[:, j]
        if self.temperature_c is not None:
            data["temperature"] = self.temperature_c
        if self.mtq_am2 is not None:
            for j, c in enumerate(OPTIONAL_GROUPS["magnetorquer"]):
                data[c] = self.mtq_am2[:, j]
        for name in sorted(self.hk):
            data[name] = self.hk[name]
        return pd.DataFrame(data)

    def to_xarray(self) -> Any:
        """The table as an xarray Dataset indexed by UTC time (needs the optional xarray)."""
        from orbitcal.notebook import frame_to_xarray, time_index

        frame = self.to_frame().drop(columns="time")
        frame.index = time_index(self.t_utc_s)
        return frame_to_xarray(frame)

    def __repr__(self) -> str:
        from orbitcal.notebook import telemetry_repr

        return telemetry_repr(self)


@dataclass(frozen=True)
class ReadResult:
    """What a reader returns: the valid rows (sorted by time) and the rejected ones."""

    telemetry: Telemetry
    rejected: list[RowError]


# --- reading -------------------------------------------------------------------------------------


def format_from_path(path: str | Path) -> TelemetryFormat:
    """The table format named by a file's extension (.csv, .parquet, .ndjson, .json)."""
    suffix = Path(path).suffix.lower()
    try:
        return _EXTENSIONS[suffix]
    except KeyError:
        raise TelemetryError(
            f"{path}: unknown telemetry extension {suffix!r}; use .csv, .parquet, .ndjson or .json"
        ) from None


def read_telemetry(path: str | Path, *, time_scale: str = "UTC") -> ReadResult:
    """Read and validate a telemetry file, its format chosen by the extension.

    Parameters
    ----------
    path : str or Path
        A ``.csv``, ``.parquet``, ``.ndjson`` (``.jsonl``) or ``.json`` file (CONTRACT section 1).
    time_scale : {"UTC", "TAI", "GPS"}
        The scale the file's times are read in; converted to UTC.

    Returns
    -------
    ReadResult
        The valid rows sorted by time and one :class:`RowError` per rejected row.

    Raises
    ------
    TelemetryError
        Unknown extension or time scale, unreadable file, missing required column.
    OSError
        The file cannot be opened.
    """
    fmt = format_from_path(path)
    data = Path(path).read_bytes()
    try:
        return parse_telemetry(data, fmt=fmt, time_scale=time_scale)
    except TelemetryError as exc:
        raise TelemetryError(f"{path}: {exc}") from None


def parse_telemetry(
    data: bytes,
    *,
    fmt: TelemetryFormat,
    time_scale: str = "UTC",
    limits: ParseLimits = DEFAULT_LIMITS,
) -> ReadResult:
    """Parse and validate a telemetry table held in memory (e.g. an HTTP upload body).

    Parameters
    ----------
    data : bytes
        The encoded table.
    fmt : {"csv", "ndjson", "json", "parquet"}
        Its format.
    time_scale : {"UTC", "TAI", "GPS"}
        The scale the times are read in.
    limits : ParseLimits
        Rows, columns, cells, nesting depth and text lengths, checked before any native parser
        sees the data.

    Returns
    -------
    ReadResult

    Raises
    ------
    TelemetryError
        Unreadable encoding, missing or repeated column, unknown format or time scale.
    LimitExceededError
        A limit of ``limits`` was exceeded (the message names it).
    """
    _check_time_scale(time_scale)
    pre_errors: dict[int, str] = {}
    # ``data`` is untrusted (an upload) and goes through pandas, pyarrow and orjson: what they
    # raise on hostile bytes that the checks above them did not foresee becomes a TelemetryError
    # naming the format (and is logged as a reader bug), never a crash.
    with reading_untrusted_input(f"{fmt} table", error=TelemetryError):
        if fmt == "csv":
            df, pre_errors = _read_csv_bytes(data, limits)
        elif fmt == "parquet":
            df = _read_parquet_bytes(data, limits)
        elif fmt == "ndjson":
            df, pre_errors = _read_ndjson_bytes(data, limits)
        elif fmt == "json":
            df, pre_errors = _read_json_array_bytes(data, limits)
        else:
            raise TelemetryError(
                f"unknown telemetry format {fmt!r}; use csv, ndjson, json or parquet"
            )
        _check_frame(df, limits)
        return _validate(df, time_scale=time_scale, pre_errors=pre_errors)


def from_frame(
    df: pd.DataFrame, *, time_scale: str = "UTC", limits: ParseLimits = DEFAULT_LIMITS
) -> ReadResult:
    """Validate a pandas table with the contract's columns (rows in upload order).

    Parameters
    ----------
    df : pandas.DataFrame
        Columns as in CONTRACT section 1; ``time`` may be strings, numbers or datetimes.
    time_scale : {"UTC", "TAI", "GPS"}
        The scale the times are read in.
    limits : ParseLimits
        Rows, columns and text lengths.

    Returns
    -------
    ReadResult
    """
    _check_time_scale(time_scale)
    df = df.reset_index(drop=True)
    _check_names([str(c) for c in df.columns], limits)
    _check_shape(len(df), len(df.columns), limits)
    _check_frame(df, limits)
    return _validate(df, time_scale=time_scale, pre_errors={})


def _check_time_scale(time_scale: str) -> None:
    if not isinstance(time_scale, str) or time_scale.strip().upper() not in TIME_SCALES:
        raise TelemetryError(
            f"unknown time scale {time_scale!r}: use one of {', '.join(TIME_SCALES)} "
            "(--time-scale / ?time_scale=)"
        )


def _check_shape(n_rows: int, n_columns: int, limits: ParseLimits) -> None:
    if n_columns > limits.max_columns:
        raise _limit("columns", n_columns, "max_columns", limits.max_columns)
    if n_rows > limits.max_rows:
        raise _limit("rows", n_rows, "max_rows", limits.max_rows)
    if n_rows * n_columns > limits.max_cells:
        raise _limit(
            f"cells ({n_rows:,} rows × {n_columns:,} columns)",
            n_rows * n_columns,
            "max_cells",
            limits.max_cells,
        )


def _check_names(names: Sequence[str], limits: ParseLimits) -> None:
    """Column names: within the count and length limits, none repeated (after trimming)."""
    if len(names) > limits.max_columns:
        raise _limit("columns", len(names), "max_columns", limits.max_columns)
    seen: dict[str, int] = {}
    for j, raw in enumerate(names):
        name = raw.strip()
        if len(name) > limits.max_name_chars:
            raise LimitExceededError(
                f"column {j + 1} has a name of {len(name):,} characters, over the limit "
                f"max_name_chars = {limits.max_name_chars}",
                limit_name="max_name_chars",
                limit=limits.max_name_chars,
            )
        if name in seen:
            raise TelemetryError(
                f"repeated column name {name!r} (columns {seen[name] + 1} and {j + 1}): "
                "each column may appear once",
                field=name,
            )
        seen[name] = j


def _check_frame(df: pd.DataFrame, limits: ParseLimits) -> None:
    """Names unique and text cells within ``max_string_chars`` (counts are checked before)."""
    _check_names([str(c) for c in df.columns], limits)
    for c in df.columns:
        col = df[c]
        if col.dtype.kind != "O" and not pd.api.types.is_string_dtype(col.dtype):
            continue
        if pd.api.types.infer_dtype(col, skipna=True) in ("string", "empty"):
            try:  # vectorised: the longest text of a plain string column
                longest = pc.max(pc.utf8_length(pa.array(col, from_pandas=True))).as_py()
                if longest is None or longest <= limits.max_string_chars:
                    continue
            except (pa.ArrowException, TypeError, ValueError):
                pass
        lengths = col.map(lambda v: len(v) if isinstance(v, str | bytes) else 0)
        too_long = np.flatnonzero(lengths.to_numpy(dtype=np.int64) > limits.max_string_chars)
        if too_long.size:
            row = int(too_long[0])
            raise LimitExceededError(
                f"row {row}: {str(c).strip()} holds {int(lengths.iloc[row]):,} characters, over "
                f"the limit max_string_chars = {limits.max_string_chars}",
                limit_name="max_string_chars",
                limit=limits.max_string_chars,
            )


def _check_utf8(data: bytes, *, what: str, header_lines: int = 1) -> None:
    """Refuse text that is not UTF-8, naming the data row (0-based) and the byte."""
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start)
        row = line - header_lines
        where = "the header" if row < 0 else f"row {row}"
        raise TelemetryError(
            f"not a readable {what} table: {where} is not UTF-8 text (byte "
            f"0x{data[exc.start]:02x} at offset {exc.start}: {exc.reason})",
            row=None if row < 0 else row,
        ) from None


def _read_csv_arrow(data: bytes, *, use_threads: bool, invalid: list[Any]) -> pa.Table:
    def on_invalid(row: Any) -> str:
        invalid.append(row)
        return "skip"

    return pa_csv.read_csv(
        io.BytesIO(data),
        read_options=pa_csv.ReadOptions(use_threads=use_threads),
        parse_options=pa_csv.ParseOptions(invalid_row_handler=on_invalid),
        convert_options=pa_csv.ConvertOptions(
            column_types={"time": pa.string()}, strings_can_be_null=True
        ),
    )


def _csv_header(data: bytes, limits: ParseLimits) -> list[str]:
    """The CSV header's column names, read in Python within the limits (before pyarrow/pandas)."""
    ends = [i for i in (data.find(b"\n"), data.find(b"\r")) if i >= 0]
    line = data[: min(ends)] if ends else data
    cap = limits.max_columns * (limits.max_name_chars + 3) + 64
    if len(line) > cap:
        n = line.count(b",") + 1
        if n > limits.max_columns:
            raise _limit("columns in the CSV header", n, "max_columns", limits.max_columns)
        raise _limit("bytes in the CSV header", len(line), "max_name_chars", limits.max_name_chars)
    _check_utf8(line, what="CSV")
    try:
        names = next(csv.reader([line.decode("utf-8")], skipinitialspace=True), [])
    except csv.Error as exc:
        raise TelemetryError(f"not a readable CSV table: the header: {exc}") from None
    _check_names(names, limits)
    return names


def _read_csv_bytes(data: bytes, limits: ParseLimits) -> tuple[pd.DataFrame, dict[int, str]]:
    """CSV → frame in data-row order plus reasons for rows with the wrong number of fields."""
    if not data.strip():
        raise TelemetryError("empty CSV: a header row with at least time,b_x,b_y,b_z is required")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # UTF-8 byte-order mark (spreadsheet exports)
    names = _csv_header(data, limits)
    # Line ends as pyarrow and pandas see them: LF, CR LF or a lone CR.
    n_breaks = data.count(b"\n") + data.count(b"\r") - data.count(b"\r\n")
    n_lines = n_breaks + (not data.endswith((b"\n", b"\r")))
    _check_shape(max(n_lines - 1, 0), len(names), limits)
    _check_utf8(data, what="CSV")
    invalid: list[Any] = []
    try:
        # Multi-threaded columnar reader; times kept as text, numbers inferred per column.
        table = _read_csv_arrow(data, use_threads=True, invalid=invalid)
        if not invalid:
            return table.to_pandas(), {}
        # Rare: ragged rows. Re-read single-threaded, which numbers them (physical lines).
        invalid.clear()
        table = _read_csv_arrow(data, use_threads=False, invalid=invalid)
    except (pa.ArrowException, ValueError):
        try:
            # pandas infers each column: Unix-second times stay numbers, ISO times stay text.
            return pd.read_csv(io.BytesIO(data), skipinitialspace=True), {}
        except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
            raise TelemetryError(f"not a readable CSV table: {exc}") from None
    # pyarrow numbers rows from 1 at the header, skipping blank lines: data row = number − 2.
    bad: dict[int, str] = {}
    for row in invalid:
        if row.number is None:  # pragma: no cover - single-threaded reads number every row
            raise TelemetryError(f"CSV row with {row.actual_columns} fields: {row.text[:60]!r}")
        bad[int(row.number) - 2] = (
            f"row has {row.actual_columns} fields, the header has {row.expected_columns}"
        )
    total = table.num_rows + len(bad)
    df = table.to_pandas()
    df.index = pd.Index(np.setdiff1d(np.arange(total), np.fromiter(bad, dtype=np.int64)))
    return df.reindex(pd.RangeIndex(total)), bad


def _parquet_type_ok(t: pa.DataType) -> bool:
    if pa.types.is_dictionary(t):
        return _parquet_type_ok(t.value_type)
    return bool(
        pa.types.is_integer(t)
        or pa.types.is_floating(t)
        or pa.types.is_boolean(t)
        or pa.types.is_string(t)
        or pa.types.is_large_string(t)
        or pa.types.is_timestamp(t)
        or pa.types.is_decimal(t)
        or pa.types.is_null(t)
    )


def _read_parquet_bytes(data: bytes, limits: ParseLimits) -> pd.DataFrame:
    """Parquet → frame, after its metadata (rows, columns, types, sizes) passed the limits."""
    try:
        pf = pq.ParquetFile(pa.BufferReader(data))
        meta = pf.metadata
        schema = pf.schema_arrow
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise TelemetryError(f"not a readable Parquet file: {exc}") from None
    names = [str(n) for n in schema.names]
    _check_names(names, limits)
    if meta.num_columns > limits.max_columns:
        raise _limit("Parquet leaf columns", meta.num_columns, "max_columns", limits.max_columns)
    _check_shape(int(meta.num_rows), len(names), limits)
    for f in schema:
        if not _parquet_type_ok(f.type):
            raise TelemetryError(
                f"column {f.name!r} has Parquet type {f.type}: the table needs flat columns of "
                "numbers, booleans, UTF-8 strings or timestamps",
                field=str(f.name),
            )
    if meta.num_row_groups > limits.max_rows:
        raise _limit("Parquet row groups", meta.num_row_groups, "max_rows", limits.max_rows)
    decoded = 0
    for i in range(meta.num_row_groups):
        group = meta.row_group(i)
        decoded += sum(
            max(int(group.column(j).total_uncompressed_size), 0) for j in range(group.num_columns)
        )
        if decoded > limits.max_decoded_bytes:
            raise _limit(
                "uncompressed Parquet bytes", decoded, "max_decoded_bytes", limits.max_decoded_bytes
            )
    try:
        table = pf.read()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise TelemetryError(f"not a readable Parquet file: {exc}") from None
    if table.num_rows != meta.num_rows:
        raise TelemetryError(
            f"Parquet file holds {table.num_rows} rows but its metadata says {meta.num_rows}"
        )
    for name, col in zip(names, table.columns, strict=True):
        t = col.type.value_type if pa.types.is_dictionary(col.type) else col.type
        if pa.types.is_string(t) or pa.types.is_large_string(t):
            _check_parquet_utf8(name, col)
    try:
        return table.to_pandas()
    except (pa.ArrowException, ValueError, UnicodeDecodeError) as exc:
        raise TelemetryError(f"Parquet file cannot be converted to a table: {exc}") from None


def _check_parquet_utf8(name: str, col: pa.ChunkedArray) -> None:
    try:
        col.validate(full=True)
        return
    except pa.ArrowInvalid:
        pass
    values = col.cast(pa.binary()) if not pa.types.is_dictionary(col.type) else None
    row = 0
    if values is not None:
        for i, v in enumerate(values.to_pylist()):
            if v is not None:
                try:
                    v.decode("utf-8")
                except UnicodeDecodeError:
                    row = i
                    break
    raise TelemetryError(
        f"row {row}: column {name!r} holds text that is not UTF-8", row=row, field=name
    )


def _n_keys(value: Any) -> int:
    if isinstance(value, dict):
        return len(value) + sum(_n_keys(v) for v in value.values())
    if isinstance(value, list):
        return sum(_n_keys(v) for v in value)
    return 0


def _records_to_frame(
    records: list[Any], pre: dict[int, str], limits: ParseLimits
) -> tuple[pd.DataFrame, dict[int, str]]:
    for i, r in enumerate(records):
        if not isinstance(r, dict):
            records[i] = {}
            pre.setdefault(i, "not a JSON object (one object per sample is required)")
    if len(records) > limits.max_rows:
        raise _limit("rows", len(records), "max_rows", limits.max_rows)
    keys: dict[str, None] = {}
    for r in records:
        keys.update(dict.fromkeys(r))
        if len(keys) > limits.max_columns:
            raise _limit("distinct keys", len(keys), "max_columns", limits.max_columns)
    _check_names(list(keys), limits)
    _check_shape(len(records), len(keys), limits)
    return pd.DataFrame.from_records(records, columns=list(keys)), pre


def _read_json_array_bytes(data: bytes, limits: ParseLimits) -> tuple[pd.DataFrame, dict[int, str]]:
    colons, depth = _check_json_structure(data, per_line=False, limits=limits)
    try:
        parsed = orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        raise TelemetryError(f"not readable JSON: {exc}") from None
    if isinstance(parsed, list) and depth <= 2:  # flat objects in an array: count in C
        n_keys = sum(map(len, (r for r in parsed if isinstance(r, dict))))
    else:
        n_keys = _n_keys(parsed)
    if n_keys != colons:
        # orjson keeps the last of repeated keys; name the object that repeats one.
        if isinstance(parsed, list):
            pre: dict[int, str] = {}
            # orjson merged them: re-read with Python's parser, which keeps every key.
            items = _loads_pairs(data) or []
            for i, r in enumerate(items):
                dup = _first_repeat(r)
                if dup is not None:
                    pre[i] = f"repeated key {dup!r} in this object"
            if not pre:
                raise TelemetryError("repeated key in a nested JSON value")
            return _records_to_frame(parsed, pre, limits)
        raise TelemetryError("repeated key in the JSON object: each column may appear once")
    if isinstance(parsed, dict) and all(isinstance(v, list) for v in parsed.values()):
        # Column-oriented JSON ({"time": [...], "b_x": [...]}) is accepted too.
        _check_names(list(parsed), limits)
        lengths = {len(v) for v in parsed.values()}
        if len(lengths) > 1:
            raise TelemetryError(
                f"JSON columns of unequal length ({', '.join(map(str, sorted(lengths)))})"
            )
        _check_shape(lengths.pop() if lengths else 0, len(parsed), limits)
        return pd.DataFrame(parsed), {}
    if not isinstance(parsed, list):
        raise TelemetryError("JSON telemetry must be an array of objects, one per sample")
    return _records_to_frame(parsed, {}, limits)


def _pairs(pairs: list[tuple[str, Any]]) -> Any:
    return _PairList(pairs)


class _PairList(list):  # type: ignore[type-arg]
    """An object read with every key kept (to find repeated ones)."""


def _first_repeat(value: Any) -> str | None:
    if isinstance(value, _PairList):
        seen: set[str] = set()
        for k, v in value:
            if k in seen:
                return str(k)
            seen.add(k)
            inner = _first_repeat(v)
            if inner is not None:
                return inner
    elif isinstance(value, list):
        for v in value:
            inner = _first_repeat(v)
            if inner is not None:
                return inner
    return None


_NDJSON_CHUNK_LINES = 65_536


def _read_ndjson_bytes(data: bytes, limits: ParseLimits) -> tuple[pd.DataFrame, dict[int, str]]:
    """NDJSON → frame: each non-blank line is exactly one JSON document, i.e. one row.

    Lines become Python objects a chunk at a time (65,536 lines), each chunk a frame at once, so
    a large body never holds all its rows as dicts together.
    """
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    colons, depth = _check_json_structure(data, per_line=True, limits=limits)
    lines = [ln for ln in data.splitlines() if ln.strip()]
    if not lines:
        raise TelemetryError("empty NDJSON: one JSON object per sample is required")
    if len(lines) > limits.max_rows:
        raise _limit("rows", len(lines), "max_rows", limits.max_rows)
    pre: dict[int, str] = {}
    keys: set[str] = set()
    n_keys = 0
    frames: list[pd.DataFrame] = []
    loads = orjson.loads
    for start in range(0, len(lines), _NDJSON_CHUNK_LINES):
        chunk = lines[start : start + _NDJSON_CHUNK_LINES]
        try:  # the common case: every line is one valid document (one C call per line)
            records: list[Any] = list(map(loads, chunk))
        except orjson.JSONDecodeError:
            records = []
            for i, ln in enumerate(chunk, start):
                try:
                    records.append(loads(ln))
                except orjson.JSONDecodeError as exc:
                    records.append({})
                    pre[i] = f"line is not valid JSON ({exc})"
        if not all(type(r) is dict for r in records):
            for i, r in enumerate(records):
                if not isinstance(r, dict):
                    records[i] = {}
                    pre[start + i] = "not a JSON object (one object per sample is required)"
        keys.update(*records)
        if len(keys) > limits.max_columns:
            raise _limit("distinct keys", len(keys), "max_columns", limits.max_columns)
        _check_names(sorted(keys), limits)
        _check_shape(len(lines), len(keys), limits)
        n_keys += sum(map(len, records)) if depth <= 1 else sum(map(_n_keys, records))
        frame = pd.DataFrame.from_records(records)
        if len(frame) != len(records):  # no key at all: keep one (empty) row per line
            frame = pd.DataFrame(index=pd.RangeIndex(len(records)))
        frames.append(frame)
    if n_keys != colons:
        # orjson keeps the last of repeated keys: find the lines that repeat one.
        for i, ln in enumerate(lines):
            if i not in pre:
                dup = _first_repeat(_loads_pairs(ln))
                if dup is not None:
                    pre[i] = f"repeated key {dup!r} in this object"
    df = frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True)
    return df, pre


def _loads_pairs(text: bytes) -> Any:
    try:
        return json.loads(text, object_pairs_hook=_pairs)
    except (ValueError, RecursionError):
        return None


# --- validation ----------------------------------------------------------------------------------


def _numeric_column(
    series: pd.Series,
) -> tuple[FloatArray, npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Column → float64, a mask of entries present but not numbers, and a mask of booleans.

    Booleans (``true``/``false`` in CSV or JSON) are not numbers: they are masked as such, never
    read as 1 and 0.
    """
    n = len(series)
    if series.dtype.kind in "iuf":
        values = series.to_numpy(dtype=np.float64, na_value=np.nan)
        return values, np.zeros(n, bool), np.zeros(n, bool)
    if series.dtype.kind == "b":
        return np.full(n, np.nan), np.ones(n, bool), np.ones(n, bool)
    is_bool = np.zeros(n, bool)
    kind = pd.api.types.infer_dtype(series, skipna=True) if series.dtype.kind == "O" else ""
    if str(series.dtype) == "boolean" or kind not in ("", "string", "empty", "floating", "integer"):
        is_bool = series.map(lambda v: isinstance(v, bool | np.bool_)).to_numpy(dtype=bool)
        if is_bool.any():
            series = series.where(~is_bool, None)
    as_num = pd.to_numeric(series, errors="coerce")
    values = as_num.to_numpy(dtype=np.float64, na_value=np.nan)
    # Literal "nan"/"inf" strings are numbers, but non-finite: treat as non-finite, not as text.
    not_number = np.asarray(series.notna().to_numpy(dtype=bool) & np.isnan(values)) | is_bool
    return values, not_number, is_bool


#: A ``23:59:60`` leap second in an ISO-8601 time.
_LEAP_SECOND = r"[Tt ]\d\d:\d\d:60(?:[.,]\d*)?\s*(?:[Zz]|[+-]\d\d:?\d\d)?\s*$"


def _leap_second_rows(series: pd.Series) -> npt.NDArray[np.bool_]:
    """Rows whose time is written as a ``23:59:60`` leap second."""
    if series.dtype.kind in "iufMb":
        return np.zeros(len(series), bool)
    try:
        arr = pa.array(series, from_pandas=True)
        if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
            if not pc.any(pc.match_substring(arr, ":60")).as_py():
                return np.zeros(len(series), bool)
            hit = pc.match_substring_regex(arr, _LEAP_SECOND)
            return np.asarray(hit.to_numpy(zero_copy_only=False), dtype=bool) & ~np.asarray(
                pc.is_null(hit).to_numpy(zero_copy_only=False), dtype=bool
            )
    except (pa.ArrowException, TypeError, ValueError):
        pass
    text = series.map(lambda v: v if isinstance(v, str) else "")
    return np.asarray(text.str.contains(_LEAP_SECOND, regex=True).to_numpy(dtype=bool))


def _parse_times(series: pd.Series) -> tuple[FloatArray, dict[int, str]]:
    """Time column → seconds in the declared scale.

    Fast pyarrow paths for a clean text column of ISO-8601 times or of Unix-second numbers; any
    irregular column goes through :func:`orbitcal.timescales.parse_time_values`, which names
    every bad row.
    """
    if series.dtype.kind not in "iufM":
        try:
            arr = pa.array(series, from_pandas=True)
            if not (pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type)):
                raise TypeError("not a text column")
            if arr.null_count == 0:
                try:
                    ts = pc.cast(arr, pa.timestamp("ns", tz="UTC"))
                except pa.ArrowInvalid:
                    num = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False)
                    if np.all(np.isfinite(num)):
                        return num, {}
                else:
                    ns = ts.cast(pa.int64()).to_numpy()
                    whole = np.floor_divide(ns, 1_000_000_000)
                    t = whole.astype(np.float64) + (ns - whole * 1_000_000_000) * 1e-9
                    return t, {}
        except (pa.ArrowException, TypeError, ValueError):
            pass
    t_s, errors = parse_time_values(series)
    return np.asarray(t_s, dtype=np.float64), dict(errors)


def _add(reasons: dict[int, list[str]], rows: npt.NDArray[np.intp], text: str) -> None:
    for i in rows.tolist():
        reasons.setdefault(int(i), []).append(text)


def _validate(df: pd.DataFrame, *, time_scale: str, pre_errors: dict[int, str]) -> ReadResult:
    columns = [str(c).strip() for c in df.columns]
    df.columns = pd.Index(columns)
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing and not (pre_errors and len(pre_errors) == len(df)):
        raise TelemetryError(
            f"missing required column {missing[0]!r} "
            f"(every table needs {', '.join(REQUIRED_COLUMNS)}; "
            f"found {', '.join(columns) or 'none'})"
        )
    for group, cols in OPTIONAL_GROUPS.items():
        present = [c for c in cols if c in columns]
        if present and len(present) != len(cols):
            absent = [c for c in cols if c not in columns]
            raise TelemetryError(
                f"partial {group} columns: {', '.join(present)} given without "
                f"{', '.join(absent)} (all of {', '.join(cols)} or none)"
            )
    unknown = [c for c in columns if c not in _KNOWN_COLUMNS and not c.startswith(HK_PREFIX)]
    if unknown:
        warnings.warn(
            f"ignoring unknown telemetry columns: {', '.join(unknown)} "
            "(housekeeping channels must be named hk_<name>)",
            stacklevel=3,
        )

    n = len(df)
    reasons: dict[int, list[str]] = {i: [r] for i, r in pre_errors.items()}
    if n == 0 or missing:
        return ReadResult(
            _empty_telemetry(), [RowError(i, "; ".join(r)) for i, r in reasons.items()]
        )

    # Time: parse, convert scale, range.
    t_read, t_errors = _parse_times(df["time"])
    leap = _leap_second_rows(df["time"])
    for i in np.flatnonzero(leap).tolist():
        t_errors[i] = (
            f"time {str(df['time'].iloc[i]).strip()!r} is a leap second (23:59:60): UTC seconds "
            "since 1970 cannot hold it apart from the next 00:00:00, so it is not stored; send "
            "this sample with time_scale=TAI or GPS"
        )
    if leap.any():
        t_read = np.where(leap, np.nan, t_read)
    for i, why in t_errors.items():
        if i not in pre_errors:
            reasons.setdefault(i, []).append(why)
    try:
        t_utc = to_utc_s(t_read, scale=time_scale)
    except TimeScaleError as exc:  # pragma: no cover - checked above
        raise TelemetryError(str(exc)) from None
    finite_t = np.isfinite(t_read)
    out_of_range = finite_t & ((t_read < T_MIN_S) | (t_read > T_MAX_S))
    _add(reasons, np.flatnonzero(out_of_range), "time outside 1900–2200")
    no_leap = finite_t & ~out_of_range & ~np.isfinite(t_utc)
    _add(reasons, np.flatnonzero(no_leap), f"time before 1972 cannot be read as {time_scale}")
    if time_scale.strip().upper() != "UTC":
        # A TAI/GPS instant inside a UTC leap second has no POSIX UTC time of its own.
        ok = finite_t & ~out_of_range & np.isfinite(t_utc)
        back = np.full(n, np.nan)
        back[ok] = from_utc_s(t_utc[ok], scale=time_scale)
        in_leap = ok & (np.abs(back - t_read) > 1e-6)
        for i in np.flatnonzero(in_leap).tolist():
            reasons.setdefault(i, []).append(
                f"time falls in the leap second 23:59:60 UTC before "
                f"{_iso_z(t_utc[i : i + 1])[0]}: UTC seconds since 1970 cannot hold it apart "
                "from the next second, so it is not stored"
            )

    def numeric_block(cols: Sequence[str]) -> FloatArray:
        out = np.empty((n, len(cols)))
        for j, c in enumerate(cols):
            values, not_number, is_bool = _numeric_column(df[c])
            out[:, j] = values
            _add(reasons, np.flatnonzero(is_bool), f"{c} is a boolean (true/false), not a number")
            _add(reasons, np.flatnonzero(not_number & ~is_bool), f"{c} is not a number")
            nonfinite = ~np.isfinite(values) & ~not_number
            _add(reasons, np.flatnonzero(nonfinite), f"{c} is missing or not finite")
        return out

    b = numeric_block(("b_x", "b_y", "b_z"))
    b_norm = np.linalg.norm(b, axis=1)
    _add(reasons, np.flatnonzero(b_norm > B_ABSURD_NT), f"|b| above {B_ABSURD_NT:g} nT")

    q: FloatArray | None = None
    r: FloatArray | None = None
    temp: FloatArray | None = None
    mtq: FloatArray | None = None
    if "q_w" in columns:
        q = numeric_block(OPTIONAL_GROUPS["quaternion"])
        q_norm = np.linalg.norm(q, axis=1)
        bad = np.isfinite(q_norm) & (np.abs(q_norm - 1.0) > QUAT_NORM_TOL)
        for i in np.flatnonzero(bad).tolist():
            reasons.setdefault(i, []).append(
                f"quaternion q_w,q_x,q_y,q_z not unit (|q| = {q_norm[i]:.6g}, tolerance "
                f"{QUAT_NORM_TOL:g})"
            )
    if "r_x" in columns:
        r = numeric_block(OPTIONAL_GROUPS["position"])
        r_norm = np.linalg.norm(r, axis=1)
        bad = np.isfinite(r_norm) & ((r_norm < R_MIN_KM) | (r_norm > R_MAX_KM))
        for i in np.flatnonzero(bad).tolist():
            reasons.setdefault(i, []).append(
                f"position r_x,r_y,r_z at |r| = {r_norm[i]:.6g} km is not between "
                f"{R_MIN_KM:g} and {R_MAX_KM:g} km"
            )
    if "temperature" in columns:
        temp = numeric_block(("temperature",))[:, 0]
        _add(reasons, np.flatnonzero(temp < -273.15), "temperature below absolute zero")
    if "mtq_x" in columns:
        mtq = numeric_block(OPTIONAL_GROUPS["magnetorquer"])
    hk: dict[str, npt.NDArray[Any]] = {}
    for c in columns:
        if not c.startswith(HK_PREFIX):
            continue
        values, not_number, is_bool = _numeric_column(df[c])
        if is_bool.any():
            # A flag channel: kept as the text "true"/"false", never as the numbers 1 and 0.
            col = df[c].astype(object)
            text = col.map(
                lambda v: ("true" if v else "false") if isinstance(v, bool | np.bool_) else v
            )
            hk[c] = text.where(col.notna(), "").astype(str).to_numpy(object)
        elif not_number.any():
            # A text channel (flags, modes): kept as str, never rejected.
            hk[c] = df[c].astype(object).where(df[c].notna(), "").astype(str).to_numpy(object)
        else:
            hk[c] = values
            _add(reasons, np.flatnonzero(~np.isfinite(values)), f"{c} is missing or not finite")

    # Duplicate times among rows valid so far: keep the first in upload order.
    rejected_mask = np.zeros(n, dtype=bool)
    if reasons:
        rejected_mask[np.fromiter(reasons.keys(), dtype=np.intp)] = True
    candidates = np.flatnonzero(~rejected_mask)
    # Times are stored to the microsecond: rows equal at that resolution are duplicates.
    t_c = np.rint(t_utc[candidates] * 1e6)
    order = np.argsort(t_c, kind="stable")
    t_sorted = t_c[order]
    dup_sorted = np.zeros(t_sorted.shape, dtype=bool)
    dup_sorted[1:] = t_sorted[1:] == t_sorted[:-1]
    if dup_sorted.any():
        # First row of each run of equal times (in upload order, thanks to the stable sort).
        first_pos = np.maximum.accumulate(np.where(~dup_sorted, np.arange(t_sorted.size), 0))
        for k in np.flatnonzero(dup_sorted).tolist():
            row = int(candidates[order[k]])
            first = int(candidates[order[first_pos[k]]])
            same = "" if t_utc[row] == t_utc[first] else " at microsecond resolution"
            reasons.setdefault(row, []).append(
                f"duplicate time {_iso_z(t_utc[row : row + 1])[0]}{same} (row {first} kept)"
            )
        rejected_mask[candidates[order[dup_sorted]]] = True
        keep_sorted = candidates[order[~dup_sorted]]
    else:
        keep_sorted = candidates[order]

    idx = keep_sorted  # valid rows, ascending time (stable)
    telemetry = Telemetry(
        t_utc_s=np.ascontiguousarray(t_utc[idx]),
        b_raw_nt=np.ascontiguousarray(b[idx]),
        q_wxyz=None if q is None else np.ascontiguousarray(q[idx]),
        r_itrs_km=None if r is None else np.ascontiguousarray(r[idx]),
        temperature_c=None if temp is None else np.ascontiguousarray(temp[idx]),
        mtq_am2=None if mtq is None else np.ascontiguousarray(mtq[idx]),
        hk={k: v[idx] for k, v in hk.items()},
    )
    for i, why in pre_errors.items():
        reasons[i] = [why]  # an unreadable row has no other fields worth reporting
    rejected = [RowError(i, "; ".join(reasons[i])) for i in sorted(reasons)]
    return ReadResult(telemetry, rejected)


def _empty_telemetry() -> Telemetry:
    return Telemetry(t_utc_s=np.empty(0), b_raw_nt=np.empty((0, 3)))


# --- writing -------------------------------------------------------------------------------------


def _iso_z(t_utc_s: npt.ArrayLike) -> npt.NDArray[np.str_]:
    """POSIX seconds of UTC → ISO-8601 ``YYYY-MM-DDTHH:MM:SS.ffffffZ`` (vectorised, µs)."""
    t = np.asarray(t_utc_s, dtype=np.float64)
    whole = np.floor(t)
    us = whole.astype(np.int64) * 1_000_000 + np.round((t - whole) * 1e6).astype(np.int64)
    text = np.datetime_as_string(us.astype("datetime64[us]"), unit="us")
    return np.char.add(text, "Z")


def write_telemetry(path: str | Path, telemetry: Telemetry) -> None:
    """Write a table in the format named by the extension (CONTRACT section 1 columns).

    Times are written as ISO-8601 UTC with ``Z`` and microseconds; floats at full precision
    (they read back bit-for-bit).

    Parameters
    ----------
    path : str or Path
        ``.csv``, ``.parquet``, ``.ndjson`` (``.jsonl``) or ``.json``.
    telemetry : Telemetry
        The table.
    """
    fmt = format_from_path(path)
    df = telemetry.to_frame()
    Path(path).write_bytes(_encode_frame(df, fmt))


def _encode_frame(df: pd.DataFrame, fmt: TelemetryFormat) -> bytes:
    if fmt in ("csv", "parquet"):
        table = pa.Table.from_pandas(df, preserve_index=False)
        sink = io.BytesIO()
        if fmt == "csv":
            pa_csv.write_csv(table, sink, write_options=pa_csv.WriteOptions(quoting_style="needed"))
        else:
            pq.write_table(table, sink)
        return sink.getvalue()
    keys = [str(c) for c in df.columns]
    # .tolist() gives Python floats/str in C; orjson writes NaN as null.
    cols = [np.asarray(df[c].to_numpy()).tolist() for c in keys]
    records = [dict(zip(keys, row, strict=True)) for row in zip(*cols, strict=True)]
    whole = cast(bytes, orjson.dumps(records))
    if fmt == "json":
        return whole
    if not records:
        return b""
    text_cols = [
        col for c, col in zip(keys, cols, strict=True) if c != "time" and isinstance(col[0], str)
    ]
    braces = any("{" in k or "}" in k for k in keys) or any(
        "{" in v or "}" in v for col in text_cols for v in col if isinstance(v, str)
    )
    if braces:
        return b"".join(cast(bytes, orjson.dumps(rec)) + b"\n" for rec in records)
    # One C-level dump, split between objects: valid since no key or text value holds a brace.
    return whole[1:-1].replace(b"},{", b"}\n{") + b"\n"


def write_field_csv(path: str | Path, t_utc_s: npt.ArrayLike, b_nt: npt.ArrayLike) -> None:
    """Write ``time,b_x,b_y,b_z`` (CONTRACT section 2 outputs of ``truth`` and ``apply``).

    Parameters
    ----------
    path : str or Path
        Output CSV file.
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s]; written as ISO-8601 with ``Z``.
    b_nt : array_like, shape (N, 3)
        Field components [nT] in the frame the caller documents (body frame for the CLI).
    """
    t = np.asarray(t_utc_s, dtype=np.float64)
    b = np.asarray(b_nt, dtype=np.float64)
    if b.shape != (t.shape[0], 3):
        raise ValueError(f"b_nt has shape {b.shape}, expected {(t.shape[0], 3)}")
    df = pd.DataFrame({"time": _iso_z(t), "b_x": b[:, 0], "b_y": b[:, 1], "b_z": b[:, 2]})
    Path(path).write_bytes(_encode_frame(df, "csv"))
