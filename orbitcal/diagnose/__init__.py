"""Sim-to-real gap diagnosis: effects catalogue, held-out attribution, where-analysis, report.

The public entry point is :func:`diagnose` (telemetry + orbit + :class:`DiagnosisOptions` ->
:class:`Diagnosis`, whose :class:`Report` is the CONTRACT section-5 document); the engine
underneath works on plain arrays (:class:`DiagnosisData`, :func:`attribute`), and
:func:`diagnose_data` runs the diagnosis on arrays already prepared by :func:`diagnosis_data`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from orbitcal._lazy import lazy_exports

if TYPE_CHECKING:
    from orbitcal.diagnose.api import diagnose, diagnose_data, diagnosis_data
    from orbitcal.diagnose.attribution import Attribution, EffectScore, SplitFit, attribute
    from orbitcal.diagnose.effects import CATALOGUE, EFFECT_NAMES, DiagnosisData, Effect
    from orbitcal.diagnose.html_report import report_html
    from orbitcal.diagnose.options import AttributionOptions, DiagnosisOptions
    from orbitcal.diagnose.report import build_report
    from orbitcal.diagnose.result import Diagnosis, Report

# Imported on first access (scipy and the engine are heavy; ``orbitcal diagnose --help`` needs
# only ``orbitcal.diagnose.options``).
_EXPORTS = {
    **dict.fromkeys(("diagnose", "diagnose_data", "diagnosis_data"), "orbitcal.diagnose.api"),
    **dict.fromkeys(
        ("Attribution", "EffectScore", "SplitFit", "attribute"), "orbitcal.diagnose.attribution"
    ),
    **dict.fromkeys(
        ("CATALOGUE", "EFFECT_NAMES", "DiagnosisData", "Effect"), "orbitcal.diagnose.effects"
    ),
    **dict.fromkeys(("AttributionOptions", "DiagnosisOptions"), "orbitcal.diagnose.options"),
    "build_report": "orbitcal.diagnose.report",
    "report_html": "orbitcal.diagnose.html_report",
    **dict.fromkeys(("Diagnosis", "Report"), "orbitcal.diagnose.result"),
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

__all__ = [
    "CATALOGUE",
    "EFFECT_NAMES",
    "Attribution",
    "AttributionOptions",
    "Diagnosis",
    "DiagnosisData",
    "DiagnosisOptions",
    "Effect",
    "EffectScore",
    "Report",
    "SplitFit",
    "attribute",
    "build_report",
    "diagnose",
    "diagnose_data",
    "diagnosis_data",
    "report_html",
]
