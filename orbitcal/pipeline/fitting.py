"""The run: fit a method on the earlier blocks of a table and score it on the later ones.

The fit sees only the earlier time blocks; ``metrics.holdout_rms_nt`` is measured on the later
``holdout_fraction`` of the samples, which no fit saw (docs/design.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray
from orbitcal.calibrate import METHODS, Calibration, FitData, MissingAttitudeError, fit_method
from orbitcal.calibrate.document import calibration_to_document
from orbitcal.calibrate.errors import TooFewSamplesError, UnknownMethodError
from orbitcal.calibrate.holdout import later_block_split
from orbitcal.pipeline.determination import UndeterminedError, undetermined_reason
from orbitcal.pipeline.inputs import fit_data_for_telemetry
from orbitcal.pipeline.scores import Scores, score
from orbitcal.telemetry import Telemetry

__all__ = ["CalibrationRun", "calibrate", "calibrate_telemetry", "fit_document"]


@dataclass(frozen=True)
class CalibrationRun:
    """One fit of a method on the earlier blocks of a table, scored on the later ones.

    Attributes
    ----------
    calibration : Calibration
        The fitted calibration.
    document : dict
        Its CONTRACT section-4 document (``metrics`` from the scores below).
    truth : FitData
        Raw field, reference field and housekeeping of every row of ``telemetry``.
    reference_field : str
        The reference model's full name.
    telemetry : Telemetry
        The rows fitted and scored, in time order.
    train, holdout : ndarray of bool, shape (N,)
        Rows the fit saw and the later rows it did not.
    train_scores, holdout_scores : Scores
    """

    calibration: Calibration
    document: dict[str, Any]
    truth: FitData
    reference_field: str
    telemetry: Telemetry
    train: BoolArray
    holdout: BoolArray
    train_scores: Scores
    holdout_scores: Scores

    @property
    def vector(self) -> bool:
        return (
            METHODS[self.calibration.method].vector if self.calibration.method in METHODS else True
        )


def calibrate(
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
    refuse_undetermined: bool = True,
    **method_options: Any,
) -> CalibrationRun:
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
    refuse_undetermined
        Raise :class:`UndeterminedError` for raw readings that cannot determine a calibration.
    progress
        ``progress(epoch, mse)`` during iterative fits.
    **method_options
        Passed to the calibrator (e.g. ``n_hidden``, ``restarts``, ``max_epochs``).

    Returns
    -------
    CalibrationRun
        Its document follows CONTRACT section 4; ``metrics`` holds ``holdout_rms_nt`` [nT]
        (:func:`orbitcal.metrics.primary_key` of the method), ``train_rms_nt``, the held-out
        ``holdout_scalar_rms_nt`` and (with attitude) ``holdout_norm_rms_nt``, and the sample
        counts.

    Raises
    ------
    UnknownMethodError, MissingAttitudeError, TooFewSamplesError, PoorCoverageError
        From the calibrator; ``ValueError`` from the truth pipeline (no positions and no orbit).
    UndeterminedError
        The raw readings of the fitted rows cannot determine a calibration (a stuck sensor, a
        dead axis: :func:`orbitcal.pipeline.determination.undetermined_reason`), unless
        ``refuse_undetermined`` is False (a retraining fits anyway and records the refusal).
    """
    import torch

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
    # after the method's own checks (sample counts, coverage of the reference field), which name
    # the more specific cause
    why = undetermined_reason(data.b_raw_nt[train]) if refuse_undetermined else None
    if why is not None:
        raise UndeterminedError(f"{method}: the data cannot determine a calibration: {why}")
    train_scores = score(cal, truth=data, rows=train)
    hold_scores = score(cal, truth=data, rows=hold) if np.any(hold) else train_scores
    metrics: dict[str, float] = {
        "holdout_rms_nt": hold_scores.primary(vector=spec.vector),
        "train_rms_nt": train_scores.primary(vector=spec.vector),
        "n_fit": float(np.count_nonzero(train)),
        "n_holdout": float(np.count_nonzero(hold)),
        "holdout_fraction": float(holdout_fraction),
        "holdout_scalar_rms_nt": hold_scores.scalar_rms_nt,
    }
    if hold_scores.norm_rms_nt is not None:
        metrics["holdout_norm_rms_nt"] = hold_scores.norm_rms_nt
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
    return CalibrationRun(
        calibration=cal,
        document=document,
        truth=data,
        reference_field=field_name,
        telemetry=tel,
        train=train,
        holdout=hold,
        train_scores=train_scores,
        holdout_scores=hold_scores,
    )


def calibrate_telemetry(telemetry: Telemetry, **options: Any) -> tuple[Calibration, dict[str, Any]]:
    """``(calibration, document)`` of :func:`calibrate` (same parameters)."""
    run = calibrate(telemetry, **options)
    return run.calibration, run.document


def fit_document(
    telemetry: Telemetry,
    *,
    orbit: Any,
    method: str,
    field: str,
    attitude_frame: str,
    holdout_fraction: float,
    rng: np.random.Generator,
) -> dict[str, Any]:
    """The section-4 document of :func:`calibrate` (the service's default fit function)."""
    return dict(
        calibrate(
            telemetry,
            orbit=orbit,
            method=method,
            field=field,
            attitude_frame=attitude_frame,
            holdout_fraction=holdout_fraction,
            rng=rng,
            refuse_undetermined=False,  # retrain() refuses it after scoring, saying why
        ).document
    )
