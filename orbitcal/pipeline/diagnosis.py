"""The diagnosis door of the seam (the service's); :mod:`orbitcal.diagnose` does the work."""

from __future__ import annotations

from typing import Any

import numpy as np

from orbitcal.telemetry import Telemetry

__all__ = ["diagnose"]


def diagnose(
    telemetry: Telemetry,
    *,
    orbit: Any,
    attitude_frame: str = "GCRS",
    field: str = "IGRF-14",
    prior_document: dict[str, Any] | None = None,
    rng: np.random.Generator | None = None,
) -> dict[str, Any]:
    """The section-5 diagnosis report of ``telemetry`` (:func:`orbitcal.diagnose.diagnose`).

    ``prior_document``: a calibration document (e.g. the one in service) whose linear part is a
    prior on the 12 parameters (:mod:`orbitcal.diagnose.prior`).
    """
    from orbitcal.diagnose import diagnose as run
    from orbitcal.diagnose.prior import prior_from_document

    return dict(
        run(
            telemetry,
            orbit=orbit,
            field=field,
            attitude_frame=attitude_frame,
            rng=rng if rng is not None else np.random.default_rng(0),
            calibration_prior=(
                prior_from_document(prior_document) if prior_document is not None else None
            ),
        )
    )
