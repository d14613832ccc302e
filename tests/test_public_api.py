"""Each package's public surface (``__all__``) is pinned: a change to it is a decision, made here.

Every name of each ``__all__`` must resolve (lazy re-exports included), the notebook surface of
``import orbitcal`` is the documented one (``docs/tutorial.md``), and importing ``orbitcal`` stays
light (``tests/test_cli_surface.py`` checks which packages it loads).
"""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import orbitcal

#: package -> its __all__, sorted.
PUBLIC: dict[str, list[str]] = {
    "orbitcal": [
        "Orbit",
        "OrbitcalError",
        "Telemetry",
        "__version__",
        "apply_calibration",
        "calibrate_table",
        "diagnose_table",
        "load_orbit",
        "read_table",
        "reference_field",
    ],
    "orbitcal.auxdata": [
        "ActiveTable",
        "DEFAULT_URLS",
        "KINDS",
        "ParsedTable",
        "StormMask",
        "TableFormatError",
        "active_table",
        "data_dir",
        "generation",
        "quiet_selection",
        "reload",
        "shipped_table",
        "status",
        "storm_mask",
        "table_status",
        "tables_provenance",
        "update",
        "using",
    ],
    "orbitcal.calibrate": [
        "AffineCalibration",
        "Calibration",
        "CalibrationError",
        "DEFAULT_METHOD",
        "DocumentError",
        "FitData",
        "LMBPCalibration",
        "METHODS",
        "MethodSpec",
        "MissingAttitudeError",
        "PoorCoverageError",
        "TooFewSamplesError",
        "UndeterminedFitError",
        "UnknownMethodError",
        "calibration_class",
        "fit_method",
    ],
    "orbitcal.cli": [
        "COMMAND_MODULES",
        "CliError",
        "ENTRY_POINT_GROUP",
        "EXIT_INTERRUPTED",
        "Interrupted",
        "build_parser",
        "exit_code_for",
        "main",
    ],
    "orbitcal.data": ["REAL_TLES_FILE", "real_tles_text"],
    "orbitcal.export": [
        "AffineForm",
        "DEFAULT_CAL_NAMES",
        "DEFAULT_RAW_NAMES",
        "ExportError",
        "ExportOptions",
        "ExportResult",
        "FORMATS",
        "HeldOutLoss",
        "NetworkForm",
        "ProductInfo",
        "YamcsTarget",
        "affine_part",
        "calibration_form",
        "document_sha256",
        "evaluate",
        "evaluate_document",
        "export",
        "held_out_loss",
        "hk_columns",
        "parse_hk_names",
        "parse_names",
        "product_info",
    ],
    "orbitcal.ingest": [
        "Gap",
        "GraceFOOptions",
        "IngestError",
        "IngestResult",
        "IngestSummary",
        "SwarmOptions",
        "ingest_gracefo",
        "ingest_swarm",
    ],
    "orbitcal.diagnose": [
        "Attribution",
        "AttributionOptions",
        "CATALOGUE",
        "Diagnosis",
        "DiagnosisData",
        "DiagnosisOptions",
        "EFFECT_NAMES",
        "Effect",
        "EffectScore",
        "Report",
        "SplitFit",
        "attribute",
        "build_report",
        "diagnose",
        "diagnose_data",
        "diagnosis_data",
        "report_html",
    ],
    "orbitcal.field": [
        "CompositeField",
        "DEFAULT_FIELD",
        "FIELD_NAMES",
        "FieldModel",
        "FieldRangeError",
        "MAIN_FIELD_NAMES",
        "RingCurrentField",
        "SphericalHarmonicModel",
        "get_field",
        "reference_field_provenance",
    ],
    "orbitcal.pipeline": [
        "CalibrateOptions",
        "CalibrationRun",
        "Champion",
        "EXCLUSION_REASONS",
        "FUTURE_TOLERANCE_S",
        "FitFunction",
        "PROMOTE_ALPHA",
        "PROMOTE_CHUNKS",
        "PROMOTE_MARGIN",
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
    ],
    "orbitcal.reproduce": [],
    "orbitcal.simulate": [
        "ATTITUDE_PROFILES",
        "AttitudeProfile",
        "EFFECTS",
        "EFFECT_NAMES",
        "Effect",
        "Housekeeping",
        "Inertial",
        "Injection",
        "Kinematics",
        "NadirLVLH",
        "TleSet",
        "Tumbling",
        "Wang2020Scenario",
        "World",
        "WorldFiles",
        "WorldOptions",
        "WorldState",
        "attitude_profile",
        "kinematics",
        "make_effect",
        "parse_effect_spec",
        "parse_tles",
        "read_world",
        "select_tle",
        "simulate_measured_field",
        "simulate_world",
        "wang2020_ground",
        "wang2020_orbit",
        "wang2020_time_s",
        "wang2020_truth_nt",
    ],
    "orbitcal.telemetry": [
        "B_ABSURD_NT",
        "DEFAULT_LIMITS",
        "OPTIONAL_GROUPS",
        "ParseLimits",
        "QUAT_NORM_TOL",
        "REQUIRED_COLUMNS",
        "ReadResult",
        "RowError",
        "Telemetry",
        "TelemetryError",
        "TelemetryFormat",
        "format_from_path",
        "from_frame",
        "json_scan",
        "parse_telemetry",
        "read_telemetry",
        "write_field_csv",
        "write_telemetry",
    ],
}


def test_every_package_is_pinned() -> None:
    found = {"orbitcal"} | {
        f"orbitcal.{m.name}" for m in pkgutil.iter_modules(orbitcal.__path__) if m.ispkg
    }
    assert found == set(PUBLIC)


@pytest.mark.parametrize("package", sorted(PUBLIC))
def test_all_is_pinned_and_resolves(package: str) -> None:
    module = importlib.import_module(package)
    assert sorted(module.__all__) == PUBLIC[package]
    assert len(set(module.__all__)) == len(module.__all__)
    for name in module.__all__:
        assert getattr(module, name) is not None, f"{package}.{name}"


def test_notebook_surface() -> None:
    expected = {"read_table", "load_orbit", "reference_field", "calibrate_table"}
    expected |= {"apply_calibration", "diagnose_table"}
    assert expected <= set(orbitcal.__all__)
    for name in expected:
        assert callable(getattr(orbitcal, name)) and getattr(orbitcal, name).__doc__
    with pytest.raises(AttributeError):
        orbitcal.not_a_name  # noqa: B018


def test_calibrate_table_holds_out_the_share_every_surface_holds_out() -> None:
    """The default is written out (``orbitcal.api`` loads without numpy); it must not drift from
    the one share the CLI, the pipeline and the service hold out."""
    import inspect

    from orbitcal.api import calibrate_table
    from orbitcal.calibrate.holdout import HOLDOUT_FRACTION

    default = inspect.signature(calibrate_table).parameters["holdout_fraction"].default
    assert default == HOLDOUT_FRACTION
