"""The service's seams into the library: each function here is one call into ``orbitcal``.

Everything scientific (orbits, reference field, calibration, diagnosis) happens in the library; the
service only moves data between the database and these calls.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orbitcal.telemetry import Telemetry

__all__ = [
    "apply_document",
    "apply_linear",
    "diagnose",
    "fit_calibration",
    "load_orbit",
    "reference_body_nt",
]


def load_orbit(tle: str | None, omm: dict[str, Any] | None) -> Any:
    """An ``orbitcal.orbit.Orbit`` from a TLE text or an OMM dict (raises ``ValueError``)."""
    if tle is None and omm is None:
        return None
    from orbitcal.orbit import Orbit

    if tle is None:
        assert omm is not None
        return Orbit.from_omm(omm)
    return Orbit.from_tle(tle)


def reference_body_nt(
    telemetry: Telemetry, *, orbit: Any, attitude_frame: str, field: str
) -> np.ndarray:
    """Reference field at each sample in the body frame, ``(N, 3)`` [nT]."""
    from orbitcal.truth import truth_for_telemetry

    truth = truth_for_telemetry(telemetry, orbit=orbit, attitude_frame=attitude_frame, field=field)
    if truth.b_body_nt is None:
        raise ValueError("vector calibration needs the attitude columns q_w,q_x,q_y,q_z")
    return np.asarray(truth.b_body_nt)


def fit_calibration(
    telemetry: Telemetry,
    *,
    orbit: Any,
    method: str,
    field: str,
    attitude_frame: str,
    holdout_fraction: float,
    rng: np.random.Generator,
) -> dict[str, Any]:
    """Fit a calibration on ``telemetry``; return its section-4 document."""
    from orbitcal.pipeline import calibrate_telemetry

    _calibration, document = calibrate_telemetry(
        telemetry,
        orbit=orbit,
        method=method,
        field=field,
        attitude_frame=attitude_frame,
        holdout_fraction=holdout_fraction,
        rng=rng,
    )
    return dict(document)


def apply_document(document: dict[str, Any], telemetry: Telemetry) -> np.ndarray:
    """Calibrated field ``(N, 3)`` [nT, body] with the document's full model (housekeeping too)."""
    from orbitcal.pipeline import apply_document as apply

    return np.asarray(apply(document, telemetry))


def apply_linear(document: dict[str, Any], b_raw_nt: np.ndarray) -> np.ndarray:
    """``b_cal = M @ (b_raw - o)`` with the document's ``linear`` part, ``(N, 3)`` [nT]."""
    M = np.asarray(document["linear"]["M"], dtype=np.float64)
    o = np.asarray(document["linear"]["o"], dtype=np.float64)
    return (np.asarray(b_raw_nt) - o) @ M.T


def diagnose(
    telemetry: Telemetry,
    *,
    orbit: Any,
    attitude_frame: str,
    field: str = "IGRF-14",
    prior_document: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The section-5 diagnosis report on ``telemetry`` (``orbitcal.diagnose.diagnose``).

    ``prior_document``: a calibration document (the one in service) whose linear part is a prior
    on the 12 parameters (``orbitcal.diagnose.prior``).
    """
    from orbitcal.diagnose import diagnose as run
    from orbitcal.diagnose.prior import prior_from_document

    report = run(
        telemetry,
        orbit=orbit,
        field=field,
        attitude_frame=attitude_frame,
        rng=np.random.default_rng(0),
        calibration_prior=(
            prior_from_document(prior_document) if prior_document is not None else None
        ),
    )
    return dict(report)
