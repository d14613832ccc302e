"""Sim-to-real gap diagnosis: effects catalogue, held-out attribution, where-analysis, report.

The public entry point is :func:`diagnose` (telemetry + orbit -> CONTRACT section-5 report); the
engine underneath works on plain arrays (:class:`DiagnosisData`, :func:`attribute`).
"""

from __future__ import annotations

from orbitcal.diagnose.api import diagnose, diagnose_data, diagnosis_data
from orbitcal.diagnose.attribution import Attribution, EffectScore, SplitFit, attribute
from orbitcal.diagnose.effects import CATALOGUE, EFFECT_NAMES, DiagnosisData, Effect
from orbitcal.diagnose.report import build_report, report_html

__all__ = [
    "CATALOGUE",
    "EFFECT_NAMES",
    "Attribution",
    "DiagnosisData",
    "Effect",
    "EffectScore",
    "SplitFit",
    "attribute",
    "build_report",
    "diagnose",
    "diagnose_data",
    "diagnosis_data",
    "report_html",
]
