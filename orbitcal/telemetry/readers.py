"""Readers: bytes or a file of any section-1 format → validated :class:`ReadResult`."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from orbitcal.errors import LimitExceededError, reading_untrusted_input
from orbitcal.telemetry.limits import DEFAULT_LIMITS, ParseLimits, _check_json_structure, _limit
from orbitcal.telemetry.table import (
    ReadResult,
    TelemetryError,
    TelemetryFormat,
    format_from_path,
)
from orbitcal.telemetry.validation import _validate, structured_kind
from orbitcal.timescales import (
    TIME_SCALES,
)

__all__ = ["from_frame", "parse_telemetry", "read_telemetry"]


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
        lengths = col.map(_cell_size)
        too_long = np.flatnonzero(lengths.to_numpy(dtype=np.int64) > limits.max_string_chars)
        if too_long.size:
            row = int(too_long[0])
            value = col.iloc[row]
            what = (
                "characters"
                if isinstance(value, str | bytes)
                else f"bytes as a JSON {structured_kind(value)}"
            )
            raise LimitExceededError(
                f"row {row}: {str(c).strip()} holds {int(lengths.iloc[row]):,} {what}, over "
                f"the limit max_string_chars = {limits.max_string_chars}",
                limit_name="max_string_chars",
                limit=limits.max_string_chars,
            )


def _cell_size(value: Any) -> int:
    """A cell's size against ``max_string_chars``: characters of text, serialised bytes of a
    structured value (an array or object is held to the same limit as text), 0 for a scalar."""
    if isinstance(value, str | bytes):
        return len(value)
    if structured_kind(value) is None:
        return 0
    try:
        return len(orjson.dumps(value, option=orjson.OPT_PASSTHROUGH_SUBCLASS))
    except (TypeError, orjson.JSONEncodeError):
        return len(repr(value))


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
