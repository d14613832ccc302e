"""The calibration seam: telemetry + orbit → truth → calibration → document → scores → promotion.

Every surface that fits, applies or scores a calibration goes through this module: the CLI
(``calibrate``, ``apply``), the service's retraining jobs and routes, the demo and the diagnosis
prior. It owns

- the run (:func:`calibrate` → :class:`CalibrationRun`: calibration, document, truth, the train and
  held-out masks and their :class:`Scores`);
- scoring any document through its *full* calibration, network and housekeeping included
  (:func:`score`, :func:`residuals`);
- which stored rows a retraining may use (:func:`training_window`, :func:`usable_rows`);
- the promotion decision (:func:`decide_promotion`) and a whole retraining step (:func:`retrain`).

The fit sees only the earlier time blocks; ``metrics.holdout_rms_nt`` is measured on the later
``holdout_fraction`` of the samples, which no fit saw (docs/design.md). Accuracy figures follow
:mod:`orbitcal.metrics`: for vector methods ``holdout_rms_nt`` is the RMS of the calibrated
body-frame field minus the reference field over all three components; for scalar (attitude-free)
methods, which cannot see a rotation of the sensor axes, it is the RMS of ``‖b_cal‖ − |B_ref|``.
"""

from __future__ import annotations

from orbitcal.pipeline.determination import UndeterminedError
from orbitcal.pipeline.diagnosis import diagnose
from orbitcal.pipeline.fitting import (
    CalibrateOptions,
    CalibrationRun,
    calibrate,
    calibrate_telemetry,
    fit_document,
)
from orbitcal.pipeline.inputs import fit_data_for_telemetry, orbit_from
from orbitcal.pipeline.promotion import (
    PROMOTE_ALPHA,
    PROMOTE_CHUNKS,
    PROMOTE_MARGIN,
    Promotion,
    PromotionRule,
    decide_promotion,
)
from orbitcal.pipeline.retraining import (
    Champion,
    FitFunction,
    Retraining,
    RetrainOptions,
    retrain,
)
from orbitcal.pipeline.rows import (
    EXCLUSION_REASONS,
    FUTURE_TOLERANCE_S,
    RowRules,
    RowSelection,
    TrainingRows,
    Window,
    describe_exclusions,
    gross_outlier_free,
    training_rows,
    training_window,
    usable_rows,
)
from orbitcal.pipeline.scores import Scores, apply_document, regressors_for, residuals, score

__all__ = [
    "EXCLUSION_REASONS",
    "FUTURE_TOLERANCE_S",
    "PROMOTE_ALPHA",
    "PROMOTE_CHUNKS",
    "PROMOTE_MARGIN",
    "CalibrateOptions",
    "CalibrationRun",
    "Champion",
    "FitFunction",
    "Promotion",
    "PromotionRule",
    "RetrainOptions",
    "Retraining",
    "RowRules",
    "RowSelection",
    "Scores",
    "TrainingRows",
    "UndeterminedError",
    "Window",
    "apply_document",
    "calibrate",
    "calibrate_telemetry",
    "decide_promotion",
    "describe_exclusions",
    "diagnose",
    "fit_data_for_telemetry",
    "fit_document",
    "gross_outlier_free",
    "orbit_from",
    "regressors_for",
    "residuals",
    "retrain",
    "score",
    "training_rows",
    "training_window",
    "usable_rows",
]
