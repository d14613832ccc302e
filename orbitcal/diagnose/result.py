"""What a diagnosis returns: the section-5 :class:`Report` and the :class:`Diagnosis` behind it.

A :class:`Report` is read-only: :meth:`Report.to_json` gives a fresh copy of the CONTRACT
section-5 document each time, so no caller can change what another one sees (the service's cache
keeps the report, not a dict that a route could patch).
"""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.data import DiagnosisData

__all__ = ["Diagnosis", "Report"]


@dataclass(frozen=True, eq=False)
class Report:
    """The diagnosis report (CONTRACT section 5), read-only.

    Build it with :meth:`from_json`; read it with :meth:`to_json` (a fresh JSON-ready dict:
    ``baseline``, ``verdict``, ranked ``effects``, ``where``, ``final`` and the supporting
    sections) or through the typed properties.
    """

    _document: Mapping[str, Any]

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
