"""What an ingest read, kept, dropped and flagged: the summary the CLI prints and JSON carries."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Gap", "IngestSummary"]

#: Gaps listed one by one in the summary (the count is always complete).
MAX_GAPS_LISTED = 20


@dataclass(frozen=True)
class Gap:
    """An interval without samples in one product, longer than that product's allowed step."""

    product: str
    start_utc: str
    end_utc: str
    duration_s: float

    def to_json(self) -> dict[str, Any]:
        return {
            "product": self.product,
            "start": self.start_utc,
            "end": self.end_utc,
            "duration_s": round(self.duration_s, 3),
        }


@dataclass
class IngestSummary:
    """Counts and notes of one ingest (filled in while the records stream).

    Attributes
    ----------
    mission : str
        ``"GRACE-FO"`` or ``"Swarm"``.
    spacecraft : str
        ``"GRACE C"``, ``"Swarm A"``, …
    files : list of str
        Every file read.
    records : Counter
        Records read per product (``MAG1B``, ``GNV1B``, …).
    rows : int
        Rows of the table (samples kept).
    dropped : Counter
        Samples not kept, by reason (``"after GNV1B span"``, ``"in SCA1B gap"``, …).
    flags : dict of str to Counter
        Per product, records with each quality-flag bit set (``{"SCA1B": {"bit 3": 12}}``).
    gaps : list of Gap
        The first :data:`MAX_GAPS_LISTED` gaps; ``n_gaps`` counts them all.
    columns : list of str
        The table's columns.
    notes : list of str
        Facts about the files a user should know (units corrected, short files, repeats).
    """

    mission: str
    spacecraft: str = ""
    files: list[str] = field(default_factory=list)
    records: Counter[str] = field(default_factory=Counter)
    rows: int = 0
    first_utc: str | None = None
    last_utc: str | None = None
    dropped: Counter[str] = field(default_factory=Counter)
    flags: dict[str, Counter[str]] = field(default_factory=dict)
    gaps: list[Gap] = field(default_factory=list)
    n_gaps: int = 0
    columns: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def add_gap(self, gap: Gap) -> None:
        self.n_gaps += 1
        if len(self.gaps) < MAX_GAPS_LISTED:
            self.gaps.append(gap)

    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def count_flags(self, product: str, bits_set: dict[int, int]) -> None:
        c = self.flags.setdefault(product, Counter())
        for bit, n in bits_set.items():
            if n:
                c[f"bit {bit}"] += int(n)

    def to_json(self) -> dict[str, Any]:
        """The summary as JSON-ready data."""
        return {
            "mission": self.mission,
            "spacecraft": self.spacecraft,
            "files": list(self.files),
            "records": dict(self.records),
            "rows": self.rows,
            "first": self.first_utc,
            "last": self.last_utc,
            "dropped": dict(self.dropped),
            "flags": {k: dict(v) for k, v in self.flags.items()},
            "n_gaps": self.n_gaps,
            "gaps": [g.to_json() for g in self.gaps],
            "columns": list(self.columns),
            "notes": list(self.notes),
        }

    def lines(self) -> list[str]:
        """A few lines for a terminal."""
        read = ", ".join(f"{k} {v}" for k, v in sorted(self.records.items()))
        out = [
            f"{self.spacecraft or self.mission} ({self.mission}): {self.rows} rows"
            + (f" {self.first_utc} … {self.last_utc}" if self.first_utc else ""),
            f"records read: {read}",
        ]
        n_drop = sum(self.dropped.values())
        if n_drop:
            why = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items()))
            out.append(f"dropped {n_drop}: {why}")
        for product, c in sorted(self.flags.items()):
            if c:
                out.append(
                    f"{product} flags: " + ", ".join(f"{k} {v}" for k, v in sorted(c.items()))
                )
        if self.n_gaps:
            shown = "; ".join(
                f"{g.product} {g.start_utc}+{g.duration_s:.1f}s" for g in self.gaps[:3]
            )
            out.append(f"gaps: {self.n_gaps} ({shown}{' …' if self.n_gaps > 3 else ''})")
        out.append("columns: " + ",".join(self.columns))
        out.extend(f"note: {n}" for n in self.notes)
        return out
