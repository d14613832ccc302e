"""Real missions' files in: GRACE-FO Level-1B and Swarm, read as they are published.

One public entry per mission, each giving the contract's telemetry table (section 1: times in UTC,
attitude frame GCRS, positions in ITRS km) and an :class:`IngestSummary` of what was read, kept,
dropped and flagged:

* :func:`ingest_gracefo` — GRACE-FO Level-1B RL04 ASCII (MAG1B + GNV1B + SCA1B, IHK1B
  temperatures), see :mod:`orbitcal.ingest.gracefo`;
* :func:`ingest_swarm` — Swarm MAGx_LR_1B CDF and VirES exports (CSV, CDF), see
  :mod:`orbitcal.ingest.swarm`.

With ``out`` the table is written to that file (CSV and Parquet streamed chunk by chunk);
without, it is returned in memory.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from orbitcal.ingest.errors import IngestError
from orbitcal.ingest.gracefo import GraceFOOptions, GraceFOSource
from orbitcal.ingest.output import concat_tables, write_chunks
from orbitcal.ingest.summary import Gap, IngestSummary
from orbitcal.ingest.swarm import SwarmOptions, read_swarm
from orbitcal.telemetry import Telemetry

__all__ = [
    "Gap",
    "GraceFOOptions",
    "IngestError",
    "IngestResult",
    "IngestSummary",
    "SwarmOptions",
    "ingest_gracefo",
    "ingest_swarm",
]


@dataclass(frozen=True)
class IngestResult:
    """An ingest's table (None when it was written to a file) and its summary."""

    telemetry: Telemetry | None
    summary: IngestSummary
    out: Path | None = None

    def to_json(self) -> dict[str, object]:
        doc = self.summary.to_json()
        doc["out"] = None if self.out is None else str(self.out)
        return doc


def ingest_gracefo(
    paths: Sequence[str | Path] | str | Path,
    *,
    out: str | Path | None = None,
    options: GraceFOOptions | None = None,
) -> IngestResult:
    """GRACE-FO Level-1B files (or directories of them) → the contract's telemetry table.

    Parameters
    ----------
    paths : path or sequence of paths
        MAG1B, GNV1B and SCA1B files of one satellite (IHK1B optional), one or more days, or
        directories holding them (``PROD_YYYY-MM-DD_S_04.txt``, optionally ``.gz``).
    out : path, optional
        Write the table there (format by extension) instead of returning it.
    options : GraceFOOptions, optional
        Gaps, chunk size, temperatures.

    Raises
    ------
    IngestError
        A file is missing, truncated or of a foreign layout (file, line and field named).
    """
    items = [paths] if isinstance(paths, str | Path) else list(paths)
    source = GraceFOSource.open(items, options)
    if out is not None:
        write_chunks(out, source.chunks())
        return IngestResult(None, source.summary, Path(out))
    table = concat_tables(source.chunks())
    if not len(table):
        raise IngestError(str(items[0]), "no samples left (see the summary's dropped counts)")
    return IngestResult(table, source.summary)


def ingest_swarm(
    path: str | Path,
    *,
    out: str | Path | None = None,
    options: SwarmOptions | None = None,
) -> IngestResult:
    """A Swarm MAGx_LR_1B CDF or a VirES export (CSV or CDF) → the contract's telemetry table.

    See :mod:`orbitcal.ingest.swarm` for which variables are read and the frames they give.
    """
    table, summary = read_swarm(path, options or SwarmOptions())
    if out is not None:
        write_chunks(out, [table])
        return IngestResult(None, summary, Path(out))
    return IngestResult(table, summary)
