"""The diagnosis door of the seam (the service's); :mod:`orbitcal.diagnose` does the work."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.telemetry import Telemetry

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.result import Report

__all__ = ["diagnose"]


def diagnose(
    telemetry: Telemetry,
    *,
    orbit: Any,
    attitude_frame: str = "GCRS",
    field: str = "IGRF-14",
    prior_document: dict[str, Any] | None = None,
    rng: np.random.Generator | None = None,
) -> Report:
    """The section-5 diagnosis report of ``telemetry`` (:func:`orbitcal.diagnose.diagnose`).

    ``prior_document``: a calibration document (e.g. the one in service) whose linear part is a
    prior on the 12 parameters (:mod:`orbitcal.diagnose.prior`); the report names its version.
    """
    from orbitcal.diagnose.api import diagnose as run
    from orbitcal.diagnose.options import DiagnosisOptions
    from orbitcal.diagnose.prior import prior_from_document

    prior = (
        None if prior_document is None else prior_from_document(prior_document, names_version=True)
    )
    options = DiagnosisOptions(field=field, attitude_frame=attitude_frame)
    return run(telemetry, orbit=orbit, options=options, prior=prior, rng=rng).report
