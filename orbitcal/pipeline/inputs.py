"""Inputs of a fit: the orbit from a TLE/OMM, the reference field along a table."""

from __future__ import annotations

from typing import Any

import numpy as np

from orbitcal.calibrate import FitData
from orbitcal.telemetry import Telemetry

__all__ = ["fit_data_for_telemetry", "orbit_from"]


def orbit_from(tle: str | None, omm: dict[str, Any] | None) -> Any:
    """An :class:`orbitcal.orbit.Orbit` from a TLE text or an OMM dict; ``None`` for neither.

    Raises
    ------
    ValueError
        (an :class:`orbitcal.errors.OrbitProblemError` or another ``ValueError``) for a malformed
        element set.
    """
    if tle is None and omm is None:
        return None
    from orbitcal.orbit import Orbit

    if tle is None:
        assert omm is not None
        return Orbit.from_omm(omm)
    return Orbit.from_tle(tle)


def fit_data_for_telemetry(
    telemetry: Telemetry,
    *,
    orbit: Any = None,
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
) -> tuple[FitData, str]:
    """Reference field along the table (``orbitcal.truth``) packed as :class:`FitData`.

    Returns
    -------
    data, field_name
        ``data.b_ref_body_nt`` is ``None`` without quaternions; ``field_name`` is the full model
        name with its generation.
    """
    from orbitcal.truth import truth_for_telemetry

    truth = truth_for_telemetry(telemetry, orbit=orbit, attitude_frame=attitude_frame, field=field)
    x_hk, names = telemetry.regressors()
    data = FitData(
        np.asarray(telemetry.b_raw_nt, dtype=np.float64),
        None if truth.b_body_nt is None else np.asarray(truth.b_body_nt, dtype=np.float64),
        np.linalg.norm(np.asarray(truth.b_itrs_nt, dtype=np.float64), axis=1),
        x_hk,
        list(names),
    )
    return data, truth.field_name
