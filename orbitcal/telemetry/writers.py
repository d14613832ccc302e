"""Writers: UTC, ISO-8601 with ``Z`` and microseconds, in any section-1 format."""

from __future__ import annotations

import io
from pathlib import Path
from typing import cast

import numpy as np
import numpy.typing as npt
import orjson
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from orbitcal.telemetry.table import Telemetry, TelemetryFormat, format_from_path
from orbitcal.telemetry.table import iso_z as _iso_z

__all__ = ["write_field_csv", "write_telemetry"]


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
    df = telemetry.to_table_frame()
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
