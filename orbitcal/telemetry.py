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

import io
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
import pyarrow.json as pa_json
import pyarrow.parquet as pq

from orbitcal.timescales import TIME_SCALES, TimeScaleError, parse_time_values, to_utc_s

__all__ = [
    "B_ABSURD_NT",
    "OPTIONAL_GROUPS",
    "QUAT_NORM_TOL",
    "REQUIRED_COLUMNS",
    "ReadResult",
    "RowError",
    "Telemetry",
    "TelemetryError",
    "TelemetryFormat",
    "format_from_path",
    "from_frame",
    "parse_telemetry",
    "read_telemetry",
    "write_field_csv",
    "write_telemetry",
]

FloatArray = npt.NDArray[np.float64]
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

_EXTENSIONS: dict[str, TelemetryFormat] = {
    ".csv": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".ndjson": "ndjson",
    ".jsonl": "ndjson",
    ".json": "json",
}
_KNOWN_COLUMNS = frozenset(REQUIRED_COLUMNS).union(*OPTIONAL_GROUPS.values())


class TelemetryError(ValueError):
    """The table as a whole cannot be read (missing column, bad format, unknown time scale).

    Fix the file or the option named in the message; row-level problems never raise, they are
    returned as :class:`RowError` entries.
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


def parse_telemetry(data: bytes, *, fmt: TelemetryFormat, time_scale: str = "UTC") -> ReadResult:
    """Parse and validate a telemetry table held in memory (e.g. an HTTP upload body).

    Parameters
    ----------
    data : bytes
        The encoded table.
    fmt : {"csv", "ndjson", "json", "parquet"}
        Its format.
    time_scale : {"UTC", "TAI", "GPS"}
        The scale the times are read in.

    Returns
    -------
    ReadResult

    Raises
    ------
    TelemetryError
        Unreadable encoding, missing required column, unknown format or time scale.
    """
    _check_time_scale(time_scale)
    pre_errors: dict[int, str] = {}
    if fmt == "csv":
        df, pre_errors = _read_csv_bytes(data)
    elif fmt == "parquet":
        try:
            table = pq.read_table(pa.BufferReader(data))
        except (pa.ArrowException, OSError) as exc:
            raise TelemetryError(f"not a readable Parquet file: {exc}") from None
        df = table.to_pandas()
    elif fmt == "ndjson":
        df, pre_errors = _read_ndjson_bytes(data)
    elif fmt == "json":
        df = _read_json_array_bytes(data)
    else:
        raise TelemetryError(f"unknown telemetry format {fmt!r}; use csv, ndjson, json or parquet")
    return _validate(df, time_scale=time_scale, pre_errors=pre_errors)


def from_frame(df: pd.DataFrame, *, time_scale: str = "UTC") -> ReadResult:
    """Validate a pandas table with the contract's columns (rows in upload order).

    Parameters
    ----------
    df : pandas.DataFrame
        Columns as in CONTRACT section 1; ``time`` may be strings, numbers or datetimes.
    time_scale : {"UTC", "TAI", "GPS"}
        The scale the times are read in.

    Returns
    -------
    ReadResult
    """
    _check_time_scale(time_scale)
    return _validate(df.reset_index(drop=True), time_scale=time_scale, pre_errors={})


def _check_time_scale(time_scale: str) -> None:
    if not isinstance(time_scale, str) or time_scale.strip().upper() not in TIME_SCALES:
        raise TelemetryError(
            f"unknown time scale {time_scale!r}: use one of {', '.join(TIME_SCALES)} "
            "(--time-scale / ?time_scale=)"
        )


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


def _read_csv_bytes(data: bytes) -> tuple[pd.DataFrame, dict[int, str]]:
    """CSV → frame in data-row order plus reasons for rows with the wrong number of fields."""
    if not data.strip():
        raise TelemetryError("empty CSV: a header row with at least time,b_x,b_y,b_z is required")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # UTF-8 byte-order mark (spreadsheet exports)
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


def _records_to_frame(records: Sequence[Any]) -> pd.DataFrame:
    bad = [i for i, r in enumerate(records) if not isinstance(r, dict)]
    if bad:
        raise TelemetryError(f"row {bad[0]}: a JSON object per sample is required")
    return pd.DataFrame.from_records(records)


def _read_json_array_bytes(data: bytes) -> pd.DataFrame:
    try:
        parsed = orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        raise TelemetryError(f"not readable JSON: {exc}") from None
    if isinstance(parsed, dict) and all(isinstance(v, list) for v in parsed.values()):
        # Column-oriented JSON ({"time": [...], "b_x": [...]}) is accepted too.
        try:
            return pd.DataFrame(parsed)
        except ValueError as exc:
            raise TelemetryError(f"JSON columns of unequal length: {exc}") from None
    if not isinstance(parsed, list):
        raise TelemetryError("JSON telemetry must be an array of objects, one per sample")
    return _records_to_frame(parsed)


def _read_ndjson_bytes(data: bytes) -> tuple[pd.DataFrame, dict[int, str]]:
    try:
        # Columnar C++ reader for clean files (multi-threaded, no per-row Python objects).
        # pyarrow 26's reader kills the process (SIGSEGV) when the first value is not an object
        # (e.g. a body starting with ``null``), so it only sees bodies that start with ``{``.
        head = data[3:] if data.startswith(b"\xef\xbb\xbf") else data
        if not head.lstrip(b" \t\r\n").startswith(b"{"):
            raise ValueError("not an object first: parse line by line")
        table = pa_json.read_json(io.BytesIO(data))
        if table.num_rows and all(
            not pa.types.is_nested(f.type) and not pa.types.is_null(f.type) for f in table.schema
        ):
            return table.to_pandas(), {}
    except (pa.ArrowException, ValueError):
        pass
    lines = [ln for ln in data.splitlines() if ln.strip()]
    try:
        # One C-level parse of the whole body when every line is valid (the common case).
        records: list[Any] = orjson.loads(b"[" + b",".join(lines) + b"]")
        pre: dict[int, str] = {}
    except orjson.JSONDecodeError:
        records = []
        pre = {}
        for i, ln in enumerate(lines):
            try:
                records.append(orjson.loads(ln))
            except orjson.JSONDecodeError as exc:
                records.append({})
                pre[i] = f"line is not valid JSON ({exc})"
    for i, r in enumerate(records):
        if not isinstance(r, dict):
            records[i] = {}
            pre[i] = "line is not a JSON object"
    if not records:
        raise TelemetryError("empty NDJSON: one JSON object per sample is required")
    return pd.DataFrame.from_records(records), pre


# --- validation ----------------------------------------------------------------------------------


def _numeric_column(series: pd.Series) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Column → float64 and a mask of entries that were present but not numbers."""
    if series.dtype.kind in "iuf":
        return series.to_numpy(dtype=np.float64, na_value=np.nan), np.zeros(len(series), bool)
    if series.dtype.kind == "b":
        return series.to_numpy(dtype=np.float64), np.zeros(len(series), bool)
    as_num = pd.to_numeric(series, errors="coerce")
    values = as_num.to_numpy(dtype=np.float64, na_value=np.nan)
    not_number = np.asarray(series.notna().to_numpy(dtype=bool) & np.isnan(values))
    # Literal "nan"/"inf" strings are numbers, but non-finite: treat as non-finite, not as text.
    return values, not_number


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

    def numeric_block(cols: Sequence[str]) -> FloatArray:
        out = np.empty((n, len(cols)))
        for j, c in enumerate(cols):
            values, not_number = _numeric_column(df[c])
            out[:, j] = values
            _add(reasons, np.flatnonzero(not_number), f"{c} is not a number")
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
        values, not_number = _numeric_column(df[c])
        if not_number.any():
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
    t_c = t_utc[candidates]
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
            reasons.setdefault(row, []).append(
                f"duplicate time {_iso_z(t_utc[row : row + 1])[0]} (row {first} kept)"
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
