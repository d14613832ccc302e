"""Calibrations of every method on the shared Swarm A temperature/magnetorquer world, fitted once
per test session for the export tests (``tests/test_export*.py``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray

#: Every registered method (``orbitcal.calibrate.METHODS``).
ALL_METHODS = ("linear", "linear-hk", "lmbp", "lmbp-hk", "twostep", "flann", "online")

#: Agreement asked of every exact consumer (issue 21): 1e-6 nT.
EXACT_NT = 1e-6


@dataclass(frozen=True)
class Fitted:
    """A calibration document with the table it was fitted on and ``orbitcal apply``'s output."""

    document: dict[str, Any]
    telemetry: Any
    orbit: Any
    b_apply_nt: FloatArray  # orbitcal apply on every row, table order
    x_hk: FloatArray | None  # the table's housekeeping columns in the calibration's order
    holdout: Any  # boolean mask of the held-out (later) rows


_CACHE: dict[str, Fitted] = {}


def fitted(world_and_orbit: tuple[Any, Any], method: str) -> Fitted:
    """Fit ``method`` (seeded) on the world's table, once per session."""
    if method not in _CACHE:
        from orbitcal import pipeline
        from orbitcal.export import calibration_form, hk_columns

        world, orbit = world_and_orbit
        tel = world.telemetry.sort_by_time()
        run = pipeline.calibrate(
            tel, orbit=orbit, method=method, rng=np.random.default_rng(21), spacecraft="swarm-a"
        )
        doc = run.document
        _CACHE[method] = Fitted(
            document=doc,
            telemetry=tel,
            orbit=orbit,
            b_apply_nt=pipeline.apply_document(doc, tel),
            x_hk=hk_columns(calibration_form(doc), tel),
            holdout=run.holdout,
        )
    return _CACHE[method]
