"""Telemetry + orbit → truth → calibration → CONTRACT section-4 document (CLI and service).

The fit sees only the earlier time blocks; ``metrics.holdout_rms_nt`` is measured on the later
``holdout_fraction`` of the samples, which no fit saw (docs/design.md). For vector methods it is the
rms of the calibrated body-frame field minus the reference field over all three components; for
scalar (attitude-free) methods, which cannot see a rotation of the sensor axes, it is the rms of
``‖b_cal‖ − |B_ref|``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from orbitcal.calibrate import METHODS, Calibration, FitData, MissingAttitudeError, fit_method
from orbitcal.calibrate.document import calibration_from_document, calibration_to_document
from orbitcal.calibrate.errors import TooFewSamplesError, UnknownMethodError
from orbitcal.calibrate.holdout import later_block_split, rms_nt
from orbitcal.telemetry import Telemetry

__all__ = [
    "apply_document",
    "calibrate_telemetry",
    "fit_data_for_telemetry",
    "regressors_for",
]

FloatArray = NDArray[np.float64]


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


def _scores(cal: Calibration, data: FitData, vector: bool) -> dict[str, float]:
    if data.n == 0:
        return {}
    b_cal = cal.apply(data.b_raw_nt, data.x_hk if cal.hk_names else None)
    out: dict[str, float] = {}
    assert data.b_ref_mag_nt is not None
    out["scalar_rms_nt"] = rms_nt(np.linalg.norm(b_cal, axis=1) - data.b_ref_mag_nt)
    if data.b_ref_body_nt is not None:
        out["vector_rms_nt"] = rms_nt(b_cal - data.b_ref_body_nt)
    out["rms_nt"] = out["vector_rms_nt"] if vector else out["scalar_rms_nt"]
    return out


def calibrate_telemetry(
    telemetry: Telemetry,
    *,
    orbit: Any = None,
    method: str = "lmbp-hk",
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
    holdout_fraction: float = 0.25,
    rng: np.random.Generator,
    spacecraft: str = "",
    version: int = 1,
    progress: Callable[[int, float], None] | None = None,
    **method_options: Any,
) -> tuple[Calibration, dict[str, Any]]:
    """Fit ``method`` on the earlier blocks of ``telemetry`` and score it on the later ones.

    Parameters
    ----------
    telemetry
        Validated table (UTC times); positions from its ``r_x, r_y, r_z`` or from ``orbit``.
    orbit
        An :class:`orbitcal.orbit.Orbit` (TLE/OMM), needed when the table has no positions.
    method
        A name of :data:`orbitcal.calibrate.METHODS`.
    field
        Reference field model (default IGRF-14).
    attitude_frame
        ``"GCRS"`` or ``"ITRS"``: the frame of the table's quaternions.
    holdout_fraction
        Share of the latest samples held out for ``metrics.holdout_rms_nt``.
    rng
        Seeds the fit (initial network weights).
    spacecraft, version
        Written into the document (the service fills its own).
    progress
        ``progress(epoch, mse)`` during iterative fits.
    **method_options
        Passed to the calibrator (e.g. ``n_hidden``, ``restarts``, ``max_epochs``).

    Returns
    -------
    calibration, document
        The document follows CONTRACT section 4; ``metrics`` holds ``holdout_rms_nt`` [nT],
        ``train_rms_nt``, the scalar and (with attitude) vector hold-out rms, and the sample counts.

    Raises
    ------
    UnknownMethodError, MissingAttitudeError, TooFewSamplesError, PoorCoverageError
        From the calibrator; ``ValueError`` from the truth pipeline (no positions and no orbit).
    """
    if method not in METHODS:
        raise UnknownMethodError(method, sorted(METHODS))
    spec = METHODS[method]
    if len(telemetry) == 0:
        raise TooFewSamplesError(method, 0, 1)
    if spec.vector and telemetry.q_wxyz is None:
        raise MissingAttitudeError(method)
    tel = telemetry.sort_by_time()
    data, field_name = fit_data_for_telemetry(
        tel, orbit=orbit, field=field, attitude_frame=attitude_frame
    )
    train, hold = later_block_split(tel.t_utc_s, holdout_fraction)
    generator = torch.Generator().manual_seed(int(rng.integers(0, 2**62)))
    cal = fit_method(
        method, data.subset(train), generator=generator, callback=progress, **method_options
    )
    train_scores = _scores(cal, data.subset(train), spec.vector)
    hold_scores = _scores(cal, data.subset(hold), spec.vector)
    metrics: dict[str, float] = {
        "holdout_rms_nt": hold_scores.get("rms_nt", train_scores["rms_nt"]),
        "train_rms_nt": train_scores["rms_nt"],
        "n_fit": float(np.count_nonzero(train)),
        "n_holdout": float(np.count_nonzero(hold)),
        "holdout_fraction": float(holdout_fraction),
    }
    for key in ("scalar_rms_nt", "vector_rms_nt"):
        if key in hold_scores:
            metrics[f"holdout_{key}"] = hold_scores[key]
    document = calibration_to_document(
        cal,
        spacecraft=spacecraft,
        version=version,
        reference_field=field_name,
        t_start_utc_s=float(tel.t_utc_s[0]),
        t_end_utc_s=float(tel.t_utc_s[-1]),
        n_samples=len(tel),
        metrics=metrics,
    )
    document["model"]["attitude_frame"] = attitude_frame
    return cal, document


def regressors_for(cal: Calibration, telemetry: Telemetry) -> FloatArray | None:
    """The table's housekeeping columns in the order the calibration needs (``None`` if none).

    Raises
    ------
    ValueError
        When the table lacks a column the calibration was fitted with.
    """
    if not cal.hk_names:
        return None
    x_hk, names = telemetry.regressors()
    missing = [n for n in cal.hk_names if n not in names]
    if missing:
        raise ValueError(
            f"the {cal.method} calibration needs housekeeping columns {', '.join(missing)}, "
            "which the telemetry lacks"
        )
    idx = [names.index(n) for n in cal.hk_names]
    out: FloatArray = x_hk[:, idx]
    return out


def apply_document(doc: dict[str, Any], telemetry: Telemetry) -> FloatArray:
    """Calibrated field ``(N, 3)`` [nT, body frame] for each row of ``telemetry`` (table order).

    Raises
    ------
    DocumentError
        A malformed document or unknown method.
    ValueError
        The table lacks a housekeeping column the calibration uses.
    """
    cal = calibration_from_document(doc)
    return cal.apply(
        np.asarray(telemetry.b_raw_nt, dtype=np.float64), regressors_for(cal, telemetry)
    )
