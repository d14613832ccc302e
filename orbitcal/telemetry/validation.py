"""Validation, once, at the edge: a parsed frame → valid rows and one reason per rejected row."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from orbitcal.arrays import FloatArray
from orbitcal.telemetry.table import (
    _KNOWN_COLUMNS,
    B_ABSURD_NT,
    HK_PREFIX,
    OPTIONAL_GROUPS,
    QUAT_NORM_TOL,
    R_MAX_KM,
    R_MIN_KM,
    REQUIRED_COLUMNS,
    T_MAX_S,
    T_MIN_S,
    ReadResult,
    RowError,
    Telemetry,
    TelemetryError,
)
from orbitcal.telemetry.table import (
    iso_z as _iso_z,
)
from orbitcal.timescales import (
    TimeScaleError,
    from_utc_s,
    parse_time_values,
    to_utc_s,
)

__all__: list[str] = []  # private: the readers call _validate


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


def structured_kind(value: Any) -> str | None:
    """``"array"`` or ``"object"`` for a structured (non-scalar) cell, None for a scalar."""
    if isinstance(value, dict):
        return "object"
    if isinstance(value, list | tuple | set | np.ndarray):
        return "array"
    return None


def _refuse_structured(df: pd.DataFrame, pre_errors: dict[int, str]) -> dict[int, str]:
    """Rows holding an array or object in any column, refused with that reason alone.

    Every column of the table is scalar (a number, a time or a text flag): a JSON array or object
    in a cell is neither stored as its Python text nor read as a number. The cell is emptied so
    that no later step formats it; the row's reason replaces any other (as a parser's would). A
    housekeeping channel that held nothing but such cells is dropped rather than read as missing.
    """
    out = dict(pre_errors)
    for c in df.columns:
        col = df[c]
        if col.dtype.kind != "O" or pd.api.types.infer_dtype(col, skipna=True) in (
            "string",
            "empty",
            "floating",
            "integer",
            "mixed-integer-float",
            "boolean",
        ):
            continue
        kinds = col.map(structured_kind)
        rows = np.flatnonzero(kinds.notna().to_numpy(dtype=bool))
        for i in rows.tolist():
            value = col.iloc[i]
            what = f"JSON {kinds.iloc[i]} of {len(value):,} item{'s' * (len(value) != 1)}"
            out.setdefault(
                i, f"{str(c).strip()} holds a {what}, not one value: each cell is a number or text"
            )
        if rows.size:
            kept = col.where(kinds.isna(), None)
            if str(c).strip().startswith(HK_PREFIX) and not kept.notna().any():
                del df[c]  # a channel that held nothing else: no channel, not a missing value
            else:
                df[c] = kept
    return out


def _add(reasons: dict[int, list[str]], rows: npt.NDArray[np.intp], text: str) -> None:
    for i in rows.tolist():
        reasons.setdefault(int(i), []).append(text)


def _check_columns(df: pd.DataFrame, pre_errors: dict[int, str]) -> tuple[list[str], bool]:
    """Strip the column names; raise for a missing required column (unless every row was
    unreadable anyway) or a partial group; warn about unknown columns. Returns the names and
    whether a required column is missing."""
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
            stacklevel=4,  # the caller of the reader (parse_telemetry / from_frame)
        )
    return columns, bool(missing)


@dataclass
class _Rows:
    """The frame being validated and the reasons collected so far, by row."""

    df: pd.DataFrame
    reasons: dict[int, list[str]]

    @property
    def n(self) -> int:
        return len(self.df)

    def add(self, rows: npt.NDArray[np.intp], text: str) -> None:
        _add(self.reasons, rows, text)

    def numeric_block(self, cols: Sequence[str]) -> FloatArray:
        out = np.empty((self.n, len(cols)))
        for j, c in enumerate(cols):
            values, not_number, is_bool = _numeric_column(self.df[c])
            out[:, j] = values
            self.add(np.flatnonzero(is_bool), f"{c} is a boolean (true/false), not a number")
            self.add(np.flatnonzero(not_number & ~is_bool), f"{c} is not a number")
            nonfinite = ~np.isfinite(values) & ~not_number
            self.add(np.flatnonzero(nonfinite), f"{c} is missing or not finite")
        return out


def _times_utc(rows: _Rows, time_scale: str, pre_errors: dict[int, str]) -> FloatArray:
    """The time column parsed, converted from ``time_scale`` to UTC and range-checked [s]."""
    df, reasons, n = rows.df, rows.reasons, rows.n
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
    rows.add(np.flatnonzero(out_of_range), "time outside 1900–2200")
    no_leap = finite_t & ~out_of_range & ~np.isfinite(t_utc)
    rows.add(np.flatnonzero(no_leap), f"time before 1972 cannot be read as {time_scale}")
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
    return np.asarray(t_utc, dtype=np.float64)


@dataclass
class _Vectors:
    """The validated numeric columns of every row (rejected rows included, masked later)."""

    b: FloatArray
    q: FloatArray | None = None
    r: FloatArray | None = None
    temp: FloatArray | None = None
    mtq: FloatArray | None = None


def _vectors(rows: _Rows, columns: list[str]) -> _Vectors:
    """Field, attitude, position, temperature and torquer columns, with their range checks."""
    out = _Vectors(rows.numeric_block(("b_x", "b_y", "b_z")))
    b_norm = np.linalg.norm(out.b, axis=1)
    rows.add(np.flatnonzero(b_norm > B_ABSURD_NT), f"|b| above {B_ABSURD_NT:g} nT")
    if "q_w" in columns:
        out.q = rows.numeric_block(OPTIONAL_GROUPS["quaternion"])
        q_norm = np.linalg.norm(out.q, axis=1)
        bad = np.isfinite(q_norm) & (np.abs(q_norm - 1.0) > QUAT_NORM_TOL)
        for i in np.flatnonzero(bad).tolist():
            rows.reasons.setdefault(i, []).append(
                f"quaternion q_w,q_x,q_y,q_z not unit (|q| = {q_norm[i]:.6g}, tolerance "
                f"{QUAT_NORM_TOL:g})"
            )
    if "r_x" in columns:
        out.r = rows.numeric_block(OPTIONAL_GROUPS["position"])
        r_norm = np.linalg.norm(out.r, axis=1)
        bad = np.isfinite(r_norm) & ((r_norm < R_MIN_KM) | (r_norm > R_MAX_KM))
        for i in np.flatnonzero(bad).tolist():
            rows.reasons.setdefault(i, []).append(
                f"position r_x,r_y,r_z at |r| = {r_norm[i]:.6g} km is not between "
                f"{R_MIN_KM:g} and {R_MAX_KM:g} km"
            )
    if "temperature" in columns:
        out.temp = rows.numeric_block(("temperature",))[:, 0]
        rows.add(np.flatnonzero(out.temp < -273.15), "temperature below absolute zero")
    if "mtq_x" in columns:
        out.mtq = rows.numeric_block(OPTIONAL_GROUPS["magnetorquer"])
    return out


def _housekeeping(rows: _Rows, columns: list[str]) -> dict[str, npt.NDArray[Any]]:
    """``hk_*`` channels: numbers (finite), or text/flag channels kept as ``str``."""
    df = rows.df
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
            rows.add(np.flatnonzero(~np.isfinite(values)), f"{c} is missing or not finite")
    return hk


def _first_of_each_time(rows: _Rows, t_utc: FloatArray) -> npt.NDArray[np.intp]:
    """Rows valid so far, in ascending time (stable); of rows with equal times (to the
    microsecond, the stored resolution) the first in upload order is kept, the others rejected
    as duplicates."""
    reasons = rows.reasons
    rejected_mask = np.zeros(rows.n, dtype=bool)
    if reasons:
        rejected_mask[np.fromiter(reasons.keys(), dtype=np.intp)] = True
    candidates = np.flatnonzero(~rejected_mask)
    t_c = np.rint(t_utc[candidates] * 1e6)
    order = np.argsort(t_c, kind="stable")
    t_sorted = t_c[order]
    dup_sorted = np.zeros(t_sorted.shape, dtype=bool)
    dup_sorted[1:] = t_sorted[1:] == t_sorted[:-1]
    if not dup_sorted.any():
        return candidates[order]
    # First row of each run of equal times (in upload order, thanks to the stable sort).
    first_pos = np.maximum.accumulate(np.where(~dup_sorted, np.arange(t_sorted.size), 0))
    for k in np.flatnonzero(dup_sorted).tolist():
        row = int(candidates[order[k]])
        first = int(candidates[order[first_pos[k]]])
        same = "" if t_utc[row] == t_utc[first] else " at microsecond resolution"
        reasons.setdefault(row, []).append(
            f"duplicate time {_iso_z(t_utc[row : row + 1])[0]}{same} (row {first} kept)"
        )
    return candidates[order[~dup_sorted]]


def _validate(df: pd.DataFrame, *, time_scale: str, pre_errors: dict[int, str]) -> ReadResult:
    """The rows of a parsed frame that satisfy CONTRACT section 1, and one reason per other row.

    ``pre_errors``: rows the parser could not read at all (their reason replaces any other).
    """
    pre_errors = _refuse_structured(df, pre_errors)
    columns, missing = _check_columns(df, pre_errors)
    rows = _Rows(df, {i: [r] for i, r in pre_errors.items()})
    if rows.n == 0 or missing:
        return ReadResult(
            _empty_telemetry(), [RowError(i, "; ".join(r)) for i, r in rows.reasons.items()]
        )
    t_utc = _times_utc(rows, time_scale, pre_errors)
    v = _vectors(rows, columns)
    hk = _housekeeping(rows, columns)
    idx = _first_of_each_time(rows, t_utc)  # valid rows, ascending time (stable)

    def pick(a: FloatArray | None) -> FloatArray | None:
        return None if a is None else np.ascontiguousarray(a[idx])

    telemetry = Telemetry(
        t_utc_s=np.ascontiguousarray(t_utc[idx]),
        b_raw_nt=np.ascontiguousarray(v.b[idx]),
        q_wxyz=pick(v.q),
        r_itrs_km=pick(v.r),
        temperature_c=pick(v.temp),
        mtq_am2=pick(v.mtq),
        hk={k: a[idx] for k, a in hk.items()},
    )
    reasons = rows.reasons
    for i, why in pre_errors.items():
        reasons[i] = [why]  # an unreadable row has no other fields worth reporting
    rejected = [RowError(i, "; ".join(reasons[i])) for i in sorted(reasons)]
    return ReadResult(telemetry, rejected)


def _empty_telemetry() -> Telemetry:
    return Telemetry(t_utc_s=np.empty(0), b_raw_nt=np.empty((0, 3)))
