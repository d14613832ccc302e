"""What a diagnosis returns: the section-5 :class:`Report` and the :class:`Diagnosis` behind it.

A :class:`Report` is read-only: :meth:`Report.to_json` gives a fresh copy of the CONTRACT
section-5 document each time, so no caller can change what another one sees (the service's cache
keeps the report, not a dict that a route could patch).
"""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.data import DiagnosisData

__all__ = ["Diagnosis", "Report"]


@dataclass(frozen=True, eq=False)
class Report(Mapping[str, Any]):
    """The diagnosis report (CONTRACT section 5), read-only.

    Build it with :meth:`from_json`; read it with :meth:`to_json` (a fresh JSON-ready dict:
    ``baseline``, ``verdict``, ranked ``effects``, ``where``, ``final`` and the supporting
    sections), through the typed properties, or as a read-only mapping (``report["verdict"]``
    gives a copy of the section). In a notebook: a one-line ``repr``, the first screen of the
    report page as its HTML view, and :meth:`to_frame` (the candidates, or the residual by UTC
    time).
    """

    _document: Mapping[str, Any]

    def __getitem__(self, key: str) -> Any:
        return copy.deepcopy(self._document[key])

    def __iter__(self) -> Iterator[str]:
        return iter(self._document)

    def __len__(self) -> int:
        return len(self._document)

    def __repr__(self) -> str:
        from orbitcal.diagnose.first_screen import first_screen, format_number

        screen = first_screen(self._document)
        base = self._document.get("baseline") or {}
        final = self._document.get("final") or {}
        size = ""
        if screen.size and " = " in screen.size:
            size = f", {screen.size.split(' (')[0].split(';')[0]}"
        return (
            f"Report(verdict {screen.verdict}{size}; held-out RMS "
            f"{format_number(base.get('holdout_rms_nt'))} → "
            f"{format_number(final.get('holdout_rms_nt'))} nT; "
            f"{len(self._document.get('effects') or [])} candidates)"
        )

    def _repr_html_(self) -> str:
        """The report page's first screen (what is wrong, size, how sure, what next)."""
        from orbitcal.diagnose.html_report import first_screen_html

        return first_screen_html(self._document)

    def to_frame(self, kind: str = "effects") -> pd.DataFrame:
        """The report as a pandas DataFrame.

        Parameters
        ----------
        kind : {"effects", "time"}
            ``"effects"``: one row per candidate, ranked, indexed by its name (status, held-out
            RMS before and after [nT], shrink, p-value, probability when the report has one).
            ``"time"``: the residual's RMS per time bin, calibration alone and with the selected
            effects [nT], indexed by the bin's UTC time (from the report's evidence curve).
        """
        from orbitcal.diagnose.frames import effects_frame, time_frame

        if kind == "effects":
            return effects_frame(self._document)
        if kind == "time":
            return time_frame(self._document)
        raise ValueError(f"kind must be 'effects' or 'time', not {kind!r}")

    @classmethod
    def from_json(cls, document: Mapping[str, Any]) -> Report:
        """A report holding a private deep copy of ``document``."""
        return cls(MappingProxyType(copy.deepcopy(dict(document))))

    def to_json(self) -> dict[str, Any]:
        """The section-5 document as a new JSON-ready dict (the caller may change it freely)."""
        return copy.deepcopy(dict(self._document))

    def to_json_text(self, *, indent: int | None = 1) -> str:
        """The section-5 document as JSON text (as ``orbitcal diagnose --out`` writes it)."""
        return json.dumps(dict(self._document), indent=indent)

    @property
    def verdict(self) -> str:
        """The effect that explains most of the gap, or ``"none"``."""
        return str(self._document["verdict"])

    @property
    def selected(self) -> tuple[str, ...]:
        """The effects of the final model, in selection order."""
        return tuple(self._document["final"]["effects"])

    @property
    def baseline_holdout_rms_nt(self) -> float | None:
        """Held-out RMS of the calibration alone [nT] (None when not finite)."""
        value = self._document["baseline"]["holdout_rms_nt"]
        return None if value is None else float(value)

    @property
    def final_holdout_rms_nt(self) -> float | None:
        """Held-out RMS of the final model [nT] (None when not finite)."""
        value = self._document["final"]["holdout_rms_nt"]
        return None if value is None else float(value)


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """A diagnosis: the report, the attribution behind it and the arrays it ran on.

    Attributes
    ----------
    report : Report
        The section-5 report.
    attribution : Attribution
        The held-out attribution (fits, residuals, scores) the report summarises.
    data : DiagnosisData
        The arrays the diagnosis ran on (with the learned crustal candidate when it stood in
        for a crustal model).
    """

    report: Report
    attribution: Attribution
    data: DiagnosisData

    def __repr__(self) -> str:
        """One line: the report's, and how many samples it ran on (not the arrays)."""
        return f"Diagnosis({self.report!r} on {int(self.data.n)} samples)"

    def _repr_html_(self) -> str:
        return self.report._repr_html_()
