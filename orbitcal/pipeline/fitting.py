"""The run: fit a method on the earlier blocks of a table and score it on the later ones.

The fit sees only the earlier time blocks; ``metrics.holdout_rms_nt`` is measured on the later
``holdout_fraction`` of the samples, which no fit saw (docs/design.md).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from dataclasses import field as dataclass_field
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import BoolArray
from orbitcal.calibrate import (
    METHODS,
    Calibration,
    FitData,
    MethodSpec,
    MissingAttitudeError,
    fit_method,
)
from orbitcal.calibrate.document import calibration_to_document
from orbitcal.calibrate.errors import TooFewSamplesError, UnknownMethodError
from orbitcal.calibrate.holdout import HOLDOUT_FRACTION, later_block_split
from orbitcal.pipeline.determination import UndeterminedError, undetermined_reason
from orbitcal.pipeline.inputs import fit_data_for_telemetry
from orbitcal.pipeline.scores import Scores, score
from orbitcal.plausibility import check_table, document_problem
from orbitcal.telemetry import Telemetry

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "CalibrateOptions",
    "CalibrationRun",
    "calibrate",
    "calibrate_telemetry",
    "fit_document",
]


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

    def to_frame(self) -> pd.DataFrame:
        """Per sample by UTC time: held out or not, raw, calibrated, residual [nT]
        (:func:`orbitcal.notebook.run_frame`)."""
        from orbitcal.notebook import run_frame
        from orbitcal.pipeline.scores import residuals

        return run_frame(self, *residuals(self.document, self.truth))

    def to_xarray(self) -> Any:
        """:meth:`to_frame` as an xarray Dataset (needs the optional xarray)."""
        from orbitcal.notebook import frame_to_xarray

        doc = self.document
        return frame_to_xarray(
            self.to_frame(),
            attrs={"method": str(doc.get("method")), "spacecraft": str(doc.get("spacecraft"))},
        )

    def __repr__(self) -> str:
        from orbitcal.notebook import run_repr

        return run_repr(self)


@dataclass(frozen=True)
class CalibrateOptions:
    """How :func:`calibrate` fits and scores (one typed object instead of a keyword list)."""

    #: A name of :data:`orbitcal.calibrate.METHODS`.
    method: str = "lmbp-hk"
    #: Reference field model.
    field: str = "IGRF-14"
    #: ``"GCRS"`` or ``"ITRS"``: the frame of the table's quaternions.
    attitude_frame: str = "GCRS"
    #: Share of the latest samples held out for ``metrics.holdout_rms_nt`` [-].
    holdout_fraction: float = HOLDOUT_FRACTION
    #: Written into the document (the service fills its own).
    spacecraft: str = ""
    version: int = 1
    #: Raise :class:`UndeterminedError` for raw readings that cannot determine a calibration
    #: (False: fit anyway; a retraining records the refusal itself).
    refuse_undetermined: bool = True
    #: Passed to the calibrator (e.g. ``n_hidden``, ``restarts``, ``max_epochs``).
    method_options: Mapping[str, Any] = dataclass_field(default_factory=dict)

    @classmethod
    def from_keywords(cls, **keywords: Any) -> CalibrateOptions:
        """The options named as keywords; other keywords are the method's options."""
        own = {f.name for f in fields(cls)} - {"method_options"}
        return cls(
            **{k: v for k, v in keywords.items() if k in own},
            method_options={k: v for k, v in keywords.items() if k not in own},
        )


def calibrate(
    telemetry: Telemetry,
    *,
    orbit: Any = None,
    rng: np.random.Generator,
    options: CalibrateOptions | None = None,
    progress: Callable[[int, float], None] | None = None,
    **keywords: Any,
) -> CalibrationRun:
    """Fit a method on the earlier blocks of ``telemetry`` and score it on the later ones.

    Parameters
    ----------
    telemetry
        Validated table (UTC times); positions from its ``r_x, r_y, r_z`` or from ``orbit``.
    orbit
        An :class:`orbitcal.orbit.Orbit` (TLE/OMM), needed when the table has no positions.
    rng
        Seeds the fit (initial network weights).
    options
        Method, field, attitude frame, hold-out share, document names, method options
        (:class:`CalibrateOptions`).
    progress
        ``progress(epoch, mse)`` during iterative fits.
    **keywords
        Instead of ``options``: its fields as keywords (``method="linear"``), any other keyword
        being a method option (:meth:`CalibrateOptions.from_keywords`).

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
        ``options.refuse_undetermined`` is False.
    """
    if options is not None and keywords:
        raise TypeError("calibrate() takes options or keywords, not both")
    opts = options if options is not None else CalibrateOptions.from_keywords(**keywords)
    method, field, attitude_frame = opts.method, opts.field, opts.attitude_frame
    holdout_fraction = opts.holdout_fraction
    import torch

    spec = _checked_method(method, telemetry)
    tel = telemetry.sort_by_time()
    data, field_name = fit_data_for_telemetry(
        tel, orbit=orbit, field=field, attitude_frame=attitude_frame
    )
    # a table in Tesla/Gauss/µT, or on the elements of another spacecraft: named, never fitted
    # (a stuck or dead axis is named by the checks below, not as an orbit mismatch)
    stuck = undetermined_reason(data.b_raw_nt) is not None
    check_table(data.b_raw_nt, b_ref_mag_nt=data.b_ref_mag_nt, orbit=not stuck)
    train, hold = later_block_split(tel.t_utc_s, holdout_fraction)
    generator = torch.Generator().manual_seed(int(rng.integers(0, 2**62)))
    cal = fit_method(
        method, data.subset(train), generator=generator, callback=progress, **opts.method_options
    )
    # after the method's own checks (sample counts, coverage of the reference field), which name
    # the more specific cause
    why = undetermined_reason(data.b_raw_nt[train]) if opts.refuse_undetermined else None
    if why is not None:
        raise UndeterminedError(f"{method}: the data cannot determine a calibration: {why}")
    train_scores = score(cal, truth=data, rows=train)
    hold_scores = score(cal, truth=data, rows=hold) if np.any(hold) else train_scores
    metrics = _run_metrics(
        train_scores,
        hold_scores,
        train,
        hold,
        vector=spec.vector,
        holdout_fraction=holdout_fraction,
    )
    metrics["holdout_noise_nt"] = _noise_nt(cal, data.subset(hold if np.any(hold) else train))
    document = calibration_to_document(
        cal,
        spacecraft=opts.spacecraft,
        version=opts.version,
        reference_field=field_name,
        t_start_utc_s=float(tel.t_utc_s[0]),
        t_end_utc_s=float(tel.t_utc_s[-1]),
        n_samples=len(tel),
        metrics=metrics,
    )
    document["model"]["attitude_frame"] = attitude_frame
    implausible = document_problem(document)
    if implausible is not None:
        warnings.warn(
            f"{method}: the calibration is implausible for a magnetometer in nT: {implausible}; "
            "it will not be promoted or pushed",
            stacklevel=2,
        )
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


def _checked_method(method: str, telemetry: Telemetry) -> MethodSpec:
    """The method's registry entry; the calibrator's typed errors for an unknown method, an
    empty table, or a vector method without attitude."""
    if method not in METHODS:
        raise UnknownMethodError(method, sorted(METHODS))
    spec = METHODS[method]
    if len(telemetry) == 0:
        raise TooFewSamplesError(method, 0, 1)
    if spec.vector and telemetry.q_wxyz is None:
        raise MissingAttitudeError(method)
    return spec


def _noise_nt(cal: Calibration, data: FitData) -> float:
    """White-noise floor of the residual on ``data`` per component [nT]
    (:func:`orbitcal.diagnose.noise.noise_floor_nt`: second differences, which slow errors
    cancel in): what the held-out RMS is compared with. NaN for too few samples."""
    from orbitcal.diagnose.noise import noise_floor_nt
    from orbitcal.pipeline.scores import residuals

    _b, vec, scalar = residuals(cal, data)
    return noise_floor_nt(vec if vec is not None else np.asarray(scalar)[:, None])


def _run_metrics(
    train_scores: Scores,
    hold_scores: Scores,
    train: BoolArray,
    hold: BoolArray,
    *,
    vector: bool,
    holdout_fraction: float,
) -> dict[str, float]:
    """The document's ``metrics``: held-out and training RMS (the method's primary figure),
    sample counts, the held-out scalar and (with attitude) vector-norm RMS [nT]."""
    metrics: dict[str, float] = {
        "holdout_rms_nt": hold_scores.primary(vector=vector),
        "train_rms_nt": train_scores.primary(vector=vector),
        "n_fit": float(np.count_nonzero(train)),
        "n_holdout": float(np.count_nonzero(hold)),
        "holdout_fraction": float(holdout_fraction),
        "holdout_scalar_rms_nt": hold_scores.scalar_rms_nt,
    }
    if hold_scores.norm_rms_nt is not None:
        metrics["holdout_norm_rms_nt"] = hold_scores.norm_rms_nt
    return metrics


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
            rng=rng,
            options=CalibrateOptions(
                method=method,
                field=field,
                attitude_frame=attitude_frame,
                holdout_fraction=holdout_fraction,
                refuse_undetermined=False,  # retrain() refuses it after scoring, saying why
            ),
        ).document
    )
