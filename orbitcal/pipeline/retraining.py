"""A whole retraining step: fit a challenger, score challenger and champion on the same later
rows, decide the promotion."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.calibrate import METHODS, AffineCalibration, Calibration, FitData
from orbitcal.calibrate.holdout import HOLDOUT_FRACTION, later_block_split
from orbitcal.errors import NotEnoughDataError
from orbitcal.metrics import primary_key
from orbitcal.pipeline.determination import undetermined_reason
from orbitcal.pipeline.fitting import fit_document
from orbitcal.pipeline.inputs import fit_data_for_telemetry
from orbitcal.pipeline.promotion import (
    Promotion,
    PromotionRule,
    decide_promotion,
    refuse_undetermined,
)
from orbitcal.pipeline.rows import gross_outlier_free
from orbitcal.pipeline.scores import residuals
from orbitcal.plausibility import check_table, document_problem, orbit_mismatch_problem
from orbitcal.telemetry import Telemetry

__all__ = ["Champion", "FitFunction", "RetrainOptions", "Retraining", "retrain"]

#: ``fit(telemetry, *, orbit, method, field, attitude_frame, holdout_fraction, rng) -> document``
FitFunction = Callable[..., dict[str, Any]]

#: The uncalibrated readings taken as they are (``M = I``, ``o = 0``): what a first calibration
#: must beat.
IDENTITY = AffineCalibration("linear", np.eye(3), np.zeros(3))


@dataclass(frozen=True)
class Champion:
    """The calibration in service: its section-4 document and version."""

    document: dict[str, Any]
    version: int | None = None


@dataclass(frozen=True)
class RetrainOptions:
    """How a retraining fits and judges its challenger."""

    #: A name of :data:`orbitcal.calibrate.METHODS`.
    method: str
    #: Reference field model (``orbitcal.field.get_field``).
    field: str = "IGRF-14"
    #: The frame of the table's quaternions (``"GCRS"`` or ``"ITRS"``).
    attitude_frame: str = "GCRS"
    #: Share of the latest samples held out to compare calibrations on [-].
    holdout_fraction: float = HOLDOUT_FRACTION
    #: Margin, significance and chunks of the promotion rule.
    rule: PromotionRule = dataclass_field(default_factory=PromotionRule)


@dataclass(frozen=True)
class Retraining:
    """What :func:`retrain` decided: the challenger's document and the promotion."""

    document: dict[str, Any]
    promotion: Promotion
    holdout_start_utc_s: float
    holdout_end_utc_s: float
    n_holdout: int
    #: Rows left out before the fit, by reason (``"outlier"``: :func:`gross_outlier_free`).
    excluded: dict[str, int] = dataclass_field(default_factory=dict)
    #: What was asked, and the champion compared with.
    options: RetrainOptions | None = None
    champion_version: int | None = None
    #: The rows fitted and compared (after outliers): first and last time [s of UTC], count.
    data_start_utc_s: float = float("nan")
    data_end_utc_s: float = float("nan")
    n_used: int = 0

    def provenance(self, *, rows: dict[str, Any] | None = None) -> dict[str, Any]:
        """The science half of a version's provenance record, JSON-ready: method, reference
        field, attitude frame, the data, the comparison (promotion rule, held-out span, both
        RMS) and the challenger's metrics. ``rows``: the caller's row summary
        (:meth:`TrainingRows.summary`), included as ``rows`` and counted as ``data.n``."""
        from orbitcal.timescales import utc_s_to_iso

        opts = self.options or RetrainOptions(method=str(self.document.get("method", "")))
        hold = utc_s_to_iso([self.holdout_start_utc_s, self.holdout_end_utc_s])
        data = utc_s_to_iso([self.data_start_utc_s, self.data_end_utc_s])
        out: dict[str, Any] = {
            "method": self.document.get("method", opts.method),
            "reference_field": self.document.get("reference_field", opts.field),
            "attitude_frame": opts.attitude_frame,
            "data": {
                "start": data[0],
                "end": data[1],
                "n": self.n_used if rows is None else rows["used"],
            },
        }
        if rows is not None:
            out["rows"] = rows
        out["comparison"] = {
            "holdout_start": hold[0],
            "holdout_end": hold[1],
            "holdout_n": self.n_holdout,
            "champion_version": self.champion_version,
            **self.promotion.as_dict(),
        }
        out["metrics"] = self.document.get("metrics", {})
        return out


def retrain(
    telemetry: Telemetry,
    *,
    orbit: Any,
    champion: Champion | None,
    options: RetrainOptions,
    rng: np.random.Generator,
    fit: FitFunction | None = None,
) -> Retraining:
    """Fit a challenger on the earlier rows, score challenger and champion on the same later rows
    (through their full calibrations) and decide the promotion.

    A challenger the data cannot determine (:func:`.determination.undetermined_reason` on the
    fitted rows) is refused; without a champion to compare with, the challenger must beat the
    uncalibrated readings (:func:`decide_promotion`).

    Parameters
    ----------
    telemetry
        The rows to use (already chosen: :func:`training_window`, :func:`usable_rows`).
    orbit
        The spacecraft's orbit (None: positions from the table).
    champion
        The calibration in service, or None.
    options
        Method, field, attitude frame, hold-out share, promotion rule.
    fit
        ``fit(telemetry, *, orbit, method, field, attitude_frame, holdout_fraction, rng)`` → a
        document (default :func:`fit_document`; tests inject their own).

    Raises
    ------
    NotEnoughDataError
        ``holdout_fraction`` leaves no held-out rows.
    """
    from orbitcal.timescales import utc_s_to_iso

    tel, truth_all, excluded = _outlier_free(telemetry, orbit, options)
    train, hold = later_block_split(tel.t_utc_s, options.holdout_fraction)
    if not np.any(hold):
        raise NotEnoughDataError(
            "holdout_fraction leaves no held-out samples to compare calibrations on"
        )
    document = (fit or fit_document)(
        tel,
        orbit=orbit,
        method=options.method,
        field=options.field,
        attitude_frame=options.attitude_frame,
        holdout_fraction=options.holdout_fraction,
        rng=rng,
    )
    t_hold = tel.t_utc_s[hold]
    span = utc_s_to_iso([float(t_hold[0]), float(t_hold[-1])])
    promotion = _promotion(
        document,
        champion,
        truth_all.subset(hold),
        options,
        why=undetermined_reason(truth_all.b_raw_nt[train]),
        span=f"{span[0]}..{span[1]}",
    )
    return Retraining(
        document,
        promotion,
        float(t_hold[0]),
        float(t_hold[-1]),
        int(np.count_nonzero(hold)),
        excluded,
        options=options,
        champion_version=None if champion is None else champion.version,
        data_start_utc_s=float(tel.t_utc_s[0]),
        data_end_utc_s=float(tel.t_utc_s[-1]),
        n_used=len(tel),
    )


def _outlier_free(
    telemetry: Telemetry, orbit: Any, options: RetrainOptions
) -> tuple[Telemetry, FitData, dict[str, int]]:
    """The rows sorted by time without gross outliers, their fit data, and how many were left
    out (``{"outlier": n}``, empty when none)."""
    if len(telemetry) == 0:
        raise NotEnoughDataError("a retraining needs telemetry: the table is empty")
    tel = telemetry.sort_by_time()
    truth_all, _ = fit_data_for_telemetry(
        tel, orbit=orbit, field=options.field, attitude_frame=options.attitude_frame
    )
    assert truth_all.b_ref_mag_nt is not None
    # a table in Tesla/Gauss/µT is refused whole (every row would be an "outlier")
    check_table(truth_all.b_raw_nt, b_ref_mag_nt=truth_all.b_ref_mag_nt, orbit=False)
    keep = gross_outlier_free(truth_all.b_raw_nt, truth_all.b_ref_mag_nt)
    excluded = {} if keep.all() else {"outlier": int(np.count_nonzero(~keep))}
    if excluded:
        tel, truth_all = tel.select(keep), truth_all.subset(keep)
    return tel, truth_all, excluded


def _promotion(
    document: dict[str, Any],
    champion: Champion | None,
    truth: FitData,
    options: RetrainOptions,
    *,
    why: str | None,
    span: str,
) -> Promotion:
    """The promotion decision on the held-out rows ``truth``: the challenger ``document``
    against the champion (or the uncalibrated readings), refused when ``why`` says the data do
    not determine the challenger."""
    doc_method = str(document.get("method", options.method))
    vector = METHODS[doc_method].vector if doc_method in METHODS else True
    metric = primary_key(vector=vector and truth.b_ref_body_nt is not None)

    def squared(doc: dict[str, Any] | Calibration) -> FloatArray:
        _b, vec, scalar = residuals(doc, truth)
        if metric == "rms_nt":
            assert vec is not None
            return np.mean(vec**2, axis=1)
        return scalar**2

    challenger_sq = squared(document)
    champion_sq, problem = None, None
    if champion is not None:
        try:
            champion_sq = squared(champion.document)
        except ValueError as exc:  # e.g. a housekeeping column the new data lack
            problem = str(exc)
    identity_sq = squared(IDENTITY) if champion_sq is None else None
    if why is not None:
        return refuse_undetermined(
            challenger_sq, metric=metric, why=why, rule=options.rule, identity_sq_nt2=identity_sq
        )
    decision = decide_promotion(
        challenger_sq,
        champion_sq,
        metric=metric,
        champion_version=None if champion is None else champion.version,
        span=span,
        rule=options.rule,
        champion_problem=problem,
        identity_sq_nt2=identity_sq,
    )
    if not decision.promote:
        return decision
    # a challenger that would be promoted but that no magnetometer in nT can be: refused, saying
    # why (gain, reflection, held-out error, the elements of another spacecraft)
    implausible = document_problem(document, holdout_rms_nt=decision.challenger_rms_nt)
    if implausible is None and truth.b_ref_mag_nt is not None:
        implausible = orbit_mismatch_problem(truth.b_raw_nt, truth.b_ref_mag_nt)
    if implausible is None:
        return decision
    return refuse_undetermined(
        challenger_sq,
        metric=metric,
        why=implausible,
        rule=options.rule,
        identity_sq_nt2=identity_sq,
        implausible=True,
    )
