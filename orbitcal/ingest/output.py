"""Writing an ingested table: streamed chunk by chunk for CSV and Parquet, whole otherwise.

Every chunk goes through :meth:`orbitcal.telemetry.Telemetry.to_frame`, the same columns and
ISO-8601 ``Z`` times as :func:`orbitcal.telemetry.write_telemetry`; CSV and Parquet are appended
one chunk at a time (a month of MAG1B never sits in memory), NDJSON and JSON are written whole.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from orbitcal.ingest.errors import IngestError
from orbitcal.telemetry import Telemetry, format_from_path, write_telemetry

__all__ = ["concat_tables", "write_chunks"]


def concat_tables(chunks: Iterable[Telemetry]) -> Telemetry:
    """One table from chunks with the same columns (an empty table when there are none)."""
    parts = list(chunks)
    if not parts:
        return Telemetry(t_utc_s=np.empty(0), b_raw_nt=np.empty((0, 3)))
    if len(parts) == 1:
        return parts[0]

    def cat(name: str) -> np.ndarray | None:
        arrs = [getattr(p, name) for p in parts]
        return None if arrs[0] is None else np.concatenate(arrs)

    return Telemetry(
        t_utc_s=np.concatenate([p.t_utc_s for p in parts]),
        b_raw_nt=np.concatenate([p.b_raw_nt for p in parts]),
        q_wxyz=cat("q_wxyz"),
        r_itrs_km=cat("r_itrs_km"),
        temperature_c=cat("temperature_c"),
        mtq_am2=cat("mtq_am2"),
        hk={k: np.concatenate([p.hk[k] for p in parts]) for k in parts[0].hk},
    )


def write_chunks(path: str | Path, chunks: Iterable[Telemetry]) -> int:
    """Write the chunks as one table at ``path`` (format by extension); returns the row count.

    Raises
    ------
    IngestError
        No rows at all (nothing in the inputs overlapped): no empty table is written.
    """
    out = Path(path)
    fmt = format_from_path(out)
    if fmt not in ("csv", "parquet"):
        table = concat_tables(chunks)
        if not len(table):
            raise IngestError(out, "no samples left to write (see the summary's dropped counts)")
        write_telemetry(out, table)
        return len(table)
    tmp = out.with_name(out.name + ".partial")
    writer: pq.ParquetWriter | pa_csv.CSVWriter | None = None
    rows = 0
    try:
        for tel in chunks:
            if not len(tel):
                continue
            batch = pa.Table.from_pandas(tel.to_table_frame(), preserve_index=False)
            if writer is None:
                if fmt == "parquet":
                    writer = pq.ParquetWriter(tmp, batch.schema)
                else:
                    writer = pa_csv.CSVWriter(
                        tmp, batch.schema, write_options=pa_csv.WriteOptions(quoting_style="needed")
                    )
            writer.write_table(batch)
            rows += len(tel)
    except BaseException:
        if writer is not None:
            writer.close()
        tmp.unlink(missing_ok=True)
        raise
    if writer is None:
        raise IngestError(out, "no samples left to write (see the summary's dropped counts)")
    writer.close()
    tmp.replace(out)
    return rows
