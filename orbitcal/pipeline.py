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

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.calibrate import METHODS, Calibration, FitData, MissingAttitudeError, fit_method
from orbitcal.calibrate.document import calibration_from_document, calibration_to_document
from orbitcal.calibrate.errors import TooFewSamplesError, UnknownMethodError
from orbitcal.calibrate.holdout import later_block_split
from orbitcal.errors import BadInputError, NotEnoughDataError
from orbitcal.metrics import norm_rms_nt, primary_key, rms_nt, scalar_rms_nt
from orbitcal.telemetry import Telemetry

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.result import Report

__all__ = [
    "EXCLUSION_REASONS",
    "FUTURE_TOLERANCE_S",
    "PROMOTE_ALPHA",
    "PROMOTE_CHUNKS",
    "PROMOTE_MARGIN",
    "CalibrationRun",
    "Promotion",
    "Retraining",
    "RowSelection",
    "Scores",
    "TrainingRows",
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


#: A challenger must beat the champion's held-out RMS by at least this fraction [-] …
PROMOTE_MARGIN = 0.01
#: … and the gain must be significant at this level (one-sided Wilcoxon signed-rank test) [-].
PROMOTE_ALPHA = 0.01
#: Consecutive held-out chunks the paired test compares (samples within a chunk are correlated,
#: chunks nearly independent; 16 chunks give p ≥ 2⁻¹⁶ ≈ 1.5e-5).
PROMOTE_CHUNKS = 16
#: Samples dated later than this after "now" (the retraining's clock, never earlier than their
#: ingest) are in the future and never define a window [s].
FUTURE_TOLERANCE_S = 300.0

#: ``fit(telemetry, *, orbit, method, field, attitude_frame, holdout_fraction, rng) -> document``
FitFunction = Callable[..., dict[str, Any]]


# ---------------------------------------------------------------------------------------------
# Inputs


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


# ---------------------------------------------------------------------------------------------
# Scores


@dataclass(frozen=True)
class Scores:
    """Accuracy of a calibration on some rows, in the vocabulary of :mod:`orbitcal.metrics` [nT].

    ``rms_nt`` and ``norm_rms_nt`` are None without attitude (no body-frame reference).
    """

    n: int
    scalar_rms_nt: float
    rms_nt: float | None = None
    norm_rms_nt: float | None = None

    def primary(self, *, vector: bool) -> float:
        """The figure a method is judged by (:func:`orbitcal.metrics.primary_key`)."""
        if vector and self.rms_nt is not None:
            return self.rms_nt
        return self.scalar_rms_nt

    def as_dict(self) -> dict[str, float]:
        out = {"n": float(self.n), "scalar_rms_nt": self.scalar_rms_nt}
        if self.rms_nt is not None and self.norm_rms_nt is not None:
            out["rms_nt"] = self.rms_nt
            out["norm_rms_nt"] = self.norm_rms_nt
        return out


def regressors_for(cal: Calibration, telemetry: Telemetry) -> FloatArray | None:
    """The table's housekeeping columns in the order the calibration needs (``None`` if none).

    Raises
    ------
    BadInputError
        When the table lacks a column the calibration was fitted with.
    """
    if not cal.hk_names:
        return None
    x_hk, names = telemetry.regressors()
    return _columns(cal, x_hk, names)


def _columns(cal: Calibration, x_hk: FloatArray | None, names: list[str]) -> FloatArray | None:
    if not cal.hk_names:
        return None
    missing = [n for n in cal.hk_names if n not in names]
    if missing or x_hk is None:
        raise BadInputError(
            f"the {cal.method} calibration needs housekeeping columns {', '.join(missing)}, "
            "which the telemetry lacks",
            field=missing[0] if missing else None,
        )
    out: FloatArray = x_hk[:, [names.index(n) for n in cal.hk_names]]
    return out


def apply_document(doc: dict[str, Any], telemetry: Telemetry) -> FloatArray:
    """Calibrated field ``(N, 3)`` [nT, body frame] for each row of ``telemetry`` (table order),
    through the document's full calibration (network and housekeeping terms included).

    Raises
    ------
    DocumentError
        A malformed document or unknown method.
    BadInputError
        The table lacks a housekeeping column the calibration uses.
    """
    cal = calibration_from_document(doc)
    return cal.apply(
        np.asarray(telemetry.b_raw_nt, dtype=np.float64), regressors_for(cal, telemetry)
    )


def _as_calibration(document: dict[str, Any] | Calibration) -> Calibration:
    return document if isinstance(document, Calibration) else calibration_from_document(document)


def residuals(
    document: dict[str, Any] | Calibration,
    truth: FitData,
    rows: BoolArray | NDArray[np.intp] | None = None,
) -> tuple[FloatArray, FloatArray | None, FloatArray]:
    """``(b_cal, b_cal − b_ref_body, ‖b_cal‖ − |B_ref|)`` on ``rows`` of ``truth`` [nT].

    The calibration is the document's full one (network and housekeeping terms included). The
    vector residual is None without attitude.
    """
    cal = _as_calibration(document)
    data = truth if rows is None else truth.subset(rows)
    b_cal = cal.apply(data.b_raw_nt, _columns(cal, data.x_hk, list(data.hk_names)))
    vec = None if data.b_ref_body_nt is None else b_cal - data.b_ref_body_nt
    assert data.b_ref_mag_nt is not None
    return b_cal, vec, np.linalg.norm(b_cal, axis=1) - data.b_ref_mag_nt


def score(
    document: dict[str, Any] | Calibration,
    telemetry: Telemetry | None = None,
    rows: BoolArray | NDArray[np.intp] | None = None,
    *,
    truth: FitData | None = None,
    orbit: Any = None,
    field: str | None = None,
    attitude_frame: str = "GCRS",
) -> Scores:
    """Scores of a calibration document on ``rows`` of ``telemetry`` (all rows by default).

    Parameters
    ----------
    document
        A section-4 document (or a fitted :class:`Calibration`), applied in full.
    telemetry
        The table; not needed when ``truth`` is given.
    rows
        Boolean mask or index array of the rows to score.
    truth
        The reference field along ``telemetry`` (:func:`fit_data_for_telemetry`), when already
        computed; otherwise computed here from ``orbit``, ``field`` (default: the document's
        ``reference_field``) and ``attitude_frame``.
    """
    if truth is None:
        if telemetry is None:
            raise TypeError("score() needs the telemetry or its truth")
        if field is None:
            field = (
                str(document.get("reference_field") or "IGRF-14")
                if isinstance(document, dict)
                else "IGRF-14"
            )
        if rows is not None:
            telemetry, rows = telemetry.select(rows), None
        truth, _ = fit_data_for_telemetry(
            telemetry, orbit=orbit, field=field, attitude_frame=attitude_frame
        )
    cal = _as_calibration(document)
    data = truth if rows is None else truth.subset(rows)
    b_cal = cal.apply(data.b_raw_nt, _columns(cal, data.x_hk, list(data.hk_names)))
    assert data.b_ref_mag_nt is not None
    b_ref = data.b_ref_body_nt
    return Scores(
        n=int(b_cal.shape[0]),
        scalar_rms_nt=scalar_rms_nt(b_cal, data.b_ref_mag_nt),
        rms_nt=None if b_ref is None else rms_nt(b_cal, b_ref),
        norm_rms_nt=None if b_ref is None else norm_rms_nt(b_cal, b_ref),
    )


# ---------------------------------------------------------------------------------------------
# The run


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
        ).document
    )


# ---------------------------------------------------------------------------------------------
# Which rows a retraining uses


@dataclass(frozen=True)
class Window:
    """The time window a retraining (or a recent-data view) reads, and why.

    ``start_utc_s``/``end_utc_s`` are None when no sample qualifies. ``excluded`` counts the
    samples left out by reason (``"future"``: dated after now; ``"after_window"``: isolated samples
    later than the latest dense stretch).
    """

    start_utc_s: float | None
    end_utc_s: float | None
    n: int
    excluded: dict[str, int] = field(default_factory=dict)


def training_window(
    t_utc_s: NDArray[np.float64],
    *,
    window_s: float,
    min_samples: int,
    now_utc_s: float,
    future_tolerance_s: float = FUTURE_TOLERANCE_S,
) -> Window:
    """The window ``[end − window_s, end]`` a retraining fits, robust to outliers in time.

    The window ends at the latest sample time ``t`` at which ``(t − window_s, t]`` holds at least
    ``min_samples`` samples (the latest time with dense data) among the samples not in the
    future (``t ≤ now_utc_s + future_tolerance_s``). So one valid row dated 2149, or a few stray
    rows days after the rest, neither empty the window nor block retraining: they are counted in
    ``excluded``. When no window holds ``min_samples``, the one holding the most samples is
    returned (its ``n`` says how many).

    Parameters
    ----------
    t_utc_s : ndarray, shape (N,)
        Stored sample times, POSIX seconds of UTC [s], any order.
    window_s
        Window length [s].
    min_samples
        Samples a window needs to count as dense.
    now_utc_s
        The current time [s] (never earlier than the samples' ingest).
    future_tolerance_s
        Clock skew allowed before a sample counts as being in the future [s].
    """
    t = np.sort(np.asarray(t_utc_s, dtype=np.float64))
    limit = now_utc_s + future_tolerance_s
    n_future = int(t.size - np.searchsorted(t, limit, side="right"))
    t = t[: t.size - n_future]
    excluded = {"future": n_future} if n_future else {}
    if t.size == 0:
        return Window(None, None, 0, excluded)
    # samples in (t_i - window_s, t_i] for every candidate end t_i
    counts = np.arange(1, t.size + 1) - np.searchsorted(t, t - window_s, side="left")
    dense = np.flatnonzero(counts >= max(1, min_samples))
    i_end = int(dense[-1]) if dense.size else int(t.size - 1 - np.argmax(counts[::-1]))
    end = float(t[i_end])
    after = t.size - 1 - i_end
    if after:
        excluded["after_window"] = int(after)
    start = end - window_s
    return Window(start, end, int(counts[i_end]), excluded)


@dataclass(frozen=True)
class RowSelection:
    """Rows a fit may use (``mask``) and how many were left out, by reason."""

    mask: BoolArray
    excluded: dict[str, int]


def usable_rows(
    *,
    has_attitude: BoolArray,
    has_position: BoolArray,
    vector: bool,
    have_orbit: bool,
) -> RowSelection:
    """Rows usable for a fit: with attitude for vector methods, with a position without an orbit.

    Parameters
    ----------
    has_attitude, has_position : ndarray of bool, shape (N,)
        Whether each row carries all four quaternion components / all three position components.
    vector
        The method needs the body-frame reference (attitude).
    have_orbit
        A TLE/OMM gives positions for rows without their own.
    """
    mask = np.ones(has_attitude.shape, dtype=bool)
    excluded: dict[str, int] = {}
    if vector:
        n = int(np.count_nonzero(~has_attitude))
        if n:
            excluded["no_attitude"] = n
        mask &= has_attitude
    if not have_orbit:
        n = int(np.count_nonzero(mask & ~has_position))
        if n:
            excluded["no_position"] = n
        mask &= has_position
    return RowSelection(mask, excluded)


#: Why rows were left out of a retraining, in words (the keys of ``excluded`` counts).
EXCLUSION_REASONS: dict[str, str] = {
    "future": "dated in the future",
    "after_window": "isolated after the latest dense stretch of data",
    "quarantined": "quarantined",
    "no_attitude": "without attitude (q_w..q_z) for a vector method",
    "no_position": "without position (r_x..r_z) and no orbit set",
    "storm": "storm time (Kp or Dst beyond the quiet-time thresholds)",
    "outlier": "gross outliers (raw |B| far from the reference |B|)",
}


def describe_exclusions(excluded: dict[str, int]) -> str:
    """``"3 dated in the future, 12 quarantined"``: the counts in words."""
    return ", ".join(f"{n} {EXCLUSION_REASONS.get(k, k)}" for k, n in excluded.items())


@dataclass(frozen=True)
class TrainingRows:
    """The rows of a window a retraining fits, and what it left out (counts by reason)."""

    mask: BoolArray
    excluded: dict[str, int]
    #: The quiet-time record (:func:`orbitcal.auxdata.quiet_selection`), None when off.
    quiet_time: dict[str, Any] | None

    def summary(self, *, extra: dict[str, int] | None = None) -> dict[str, Any]:
        """JSON-ready ``rows`` block of a job result: used, excluded (by reason, in words)."""
        excluded = {**self.excluded, **(extra or {})}
        return {
            "used": int(np.count_nonzero(self.mask)) - sum((extra or {}).values()),
            "excluded": excluded,
            "excluded_total": sum(excluded.values()),
            "reasons": {k: EXCLUSION_REASONS.get(k, k) for k in excluded},
            "quiet_time": self.quiet_time,
        }


def training_rows(
    window: Window,
    t_utc_s: NDArray[np.float64],
    *,
    has_attitude: BoolArray,
    has_position: BoolArray,
    method: str,
    have_orbit: bool,
    min_samples: int,
    spacecraft: str = "",
    quiet_kp_max: float | None = None,
    quiet_dst_min_nt: float | None = None,
) -> TrainingRows:
    """Which rows of a window a retraining fits: :func:`usable_rows`, then quiet time.

    Parameters
    ----------
    window
        The window (:func:`training_window`), whose exclusions are carried over.
    t_utc_s, has_attitude, has_position : ndarray, shape (N,)
        The window's rows.
    method
        The calibration method (vector methods need attitude).
    have_orbit
        Rows without positions take them from a TLE/OMM.
    min_samples
        Fewer usable rows fail the retraining.
    quiet_kp_max, quiet_dst_min_nt
        Quiet-time thresholds (:func:`orbitcal.auxdata.quiet_selection`); None: off.

    Raises
    ------
    NotEnoughDataError
        No usable window, or fewer than ``min_samples`` usable rows; the message counts the rows
        left out and says why.
    """
    if window.end_utc_s is None:
        detail = f" ({describe_exclusions(window.excluded)})" if window.excluded else ""
        raise NotEnoughDataError(f"spacecraft {spacecraft} has no usable telemetry yet{detail}")
    rows = usable_rows(
        has_attitude=has_attitude,
        has_position=has_position,
        vector=METHODS[method].vector if method in METHODS else True,
        have_orbit=have_orbit,
    )
    mask, excluded = rows.mask, {**window.excluded, **rows.excluded}
    quiet = None
    if quiet_kp_max is not None or quiet_dst_min_nt is not None:
        from orbitcal.auxdata import quiet_selection

        keep, quiet = quiet_selection(
            np.asarray(t_utc_s)[mask], kp_max=quiet_kp_max, dst_min_nt=quiet_dst_min_nt
        )
        if not keep.all():
            excluded["storm"] = int(np.count_nonzero(~keep))
            mask = mask.copy()
            mask[np.flatnonzero(mask)[~keep]] = False
    n = int(np.count_nonzero(mask))
    if n < min_samples:
        from orbitcal.timescales import utc_s_to_iso

        end = utc_s_to_iso([window.end_utc_s])[0]
        span = window.end_utc_s - (window.start_utc_s or window.end_utc_s)
        left_out = f"; left out: {describe_exclusions(excluded)}" if excluded else ""
        raise NotEnoughDataError(
            f"only {n} usable samples in the {span:g} s window ending {end}; "
            f"a retraining needs at least {min_samples}{left_out}"
        )
    return TrainingRows(mask, excluded, quiet)


#: A row whose raw field magnitude departs from the reference magnitude by more than this many
#: robust standard deviations (1.4826 × MAD) of that departure …
OUTLIER_SIGMAS = 10.0
#: … and by more than this fraction of the reference magnitude is no sensor state [-].
OUTLIER_FRACTION = 0.05


def gross_outlier_free(b_raw_nt: FloatArray, b_ref_mag_nt: FloatArray) -> BoolArray:
    """``(N,)`` bool: rows whose raw magnitude is a plausible sensor reading of the reference.

    ``d = ‖b_raw‖ − |B_ref|`` varies smoothly with a real sensor's gains and offsets (a few
    percent of the field); a row is a gross outlier when ``|d − median(d)|`` exceeds both
    ``OUTLIER_SIGMAS`` robust standard deviations and ``OUTLIER_FRACTION × |B_ref|`` — a
    telemetry glitch (a field three times too large, a bit flip), which a least-squares fit would
    otherwise follow (one such row in 3000 took a linear fit from 2 to 11 nT held out).
    """
    d = np.linalg.norm(np.asarray(b_raw_nt, dtype=np.float64), axis=1) - np.asarray(
        b_ref_mag_nt, dtype=np.float64
    )
    if d.size < 3:
        return np.ones(d.size, dtype=bool)
    dev = np.abs(d - np.median(d))
    sigma = 1.4826 * float(np.median(dev))
    out: BoolArray = ~(
        (dev > OUTLIER_SIGMAS * sigma) & (dev > OUTLIER_FRACTION * np.abs(b_ref_mag_nt))
    )
    return out


# ---------------------------------------------------------------------------------------------
# Promotion


@dataclass(frozen=True)
class Promotion:
    """Whether a challenger replaces the calibration in service, and which rule decided.

    Attributes
    ----------
    promote : bool
    rule : str
        ``"first calibration"``, ``"champion cannot be scored"``, ``"margin"`` (the gain is below
        the margin), ``"significance"`` (above the margin, not significant) or
        ``"margin and significance"`` (both passed: promoted).
    reason : str
        One sentence for operators.
    metric : str
        The compared figure (``rms_nt`` or ``scalar_rms_nt``, :mod:`orbitcal.metrics`).
    challenger_rms_nt, champion_rms_nt : float or None
    gain : float or None
        ``1 − challenger/champion`` [-].
    p_value : float or None
        One-sided Wilcoxon signed-rank p-value that the challenger's per-chunk mean squared
        residual is lower (None when not tested).
    margin, alpha : float
        The rule's parameters.
    n_chunks : int
    """

    promote: bool
    rule: str
    reason: str
    metric: str
    challenger_rms_nt: float
    champion_rms_nt: float | None
    gain: float | None
    p_value: float | None
    margin: float
    alpha: float
    n_chunks: int

    def as_dict(self) -> dict[str, Any]:
        return {
            "promoted": self.promote,
            "rule": self.rule,
            "metric": self.metric,
            "challenger_rms_nt": self.challenger_rms_nt,
            "champion_rms_nt": self.champion_rms_nt,
            "gain": self.gain,
            "p_value": self.p_value,
            "margin": self.margin,
            "alpha": self.alpha,
            "test": f"one-sided Wilcoxon signed-rank over {self.n_chunks} consecutive held-out "
            "chunks of the mean squared residual (champion − challenger)",
        }


def _chunk_p_value(sq_challenger: FloatArray, sq_champion: FloatArray, n_chunks: int) -> float:
    """One-sided p-value that the challenger's chunk-mean squared residuals are lower."""
    from scipy.stats import wilcoxon

    chunks = np.array_split(np.arange(sq_challenger.shape[0]), n_chunks)
    d = np.array([sq_champion[c].mean() - sq_challenger[c].mean() for c in chunks if c.size])
    if d.size == 0 or not np.any(d != 0.0):
        return 1.0
    return float(wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)


def decide_promotion(
    challenger_sq_nt2: FloatArray,
    champion_sq_nt2: FloatArray | None,
    *,
    metric: str,
    champion_version: int | None = None,
    span: str = "",
    margin: float = PROMOTE_MARGIN,
    alpha: float = PROMOTE_ALPHA,
    n_chunks: int = PROMOTE_CHUNKS,
    champion_problem: str | None = None,
) -> Promotion:
    """Promote a challenger only for a real improvement on the same held-out rows.

    Both calibrations are judged by ``metric`` on the same time-ordered held-out rows. The
    challenger is promoted when its RMS is below ``(1 − margin) ×`` the champion's **and** the
    paired one-sided Wilcoxon signed-rank test over ``n_chunks`` consecutive chunks of the
    per-row squared residuals gives ``p < alpha`` (chunks, not rows, because neighbouring
    samples share their errors). 1.947 against 1.948 nT therefore stays rejected.

    Parameters
    ----------
    challenger_sq_nt2, champion_sq_nt2 : ndarray, shape (N,)
        Per held-out row, the squared residual whose mean is ``metric``² [nT²] (time order);
        ``champion_sq_nt2`` None when nothing is in service.
    metric
        Name of the compared figure (for the reason).
    champion_version
        Version in service (for the reason).
    span
        The held-out time span, for the reason.
    champion_problem
        Why the champion could not be scored on these rows (then the challenger is promoted).
    """
    ch_rms = float(np.sqrt(np.mean(challenger_sq_nt2)))
    where = f" on {span}" if span else ""

    def decided(
        promote: bool,
        rule: str,
        reason: str,
        cp_rms: float | None = None,
        gain: float | None = None,
        p: float | None = None,
    ) -> Promotion:
        return Promotion(
            promote=promote,
            rule=rule,
            reason=reason,
            metric=metric,
            challenger_rms_nt=ch_rms,
            champion_rms_nt=cp_rms,
            gain=gain,
            p_value=p,
            margin=margin,
            alpha=alpha,
            n_chunks=n_chunks,
        )

    if champion_sq_nt2 is None:
        if champion_problem is None:
            return decided(True, "first calibration", "first calibration of this spacecraft")
        return decided(
            True,
            "champion cannot be scored",
            f"version {champion_version} in service cannot be scored on the new data "
            f"({champion_problem}); held-out {metric} {ch_rms:.3f} nT",
        )
    cp_rms = float(np.sqrt(np.mean(champion_sq_nt2)))
    gain = 1.0 - ch_rms / cp_rms if cp_rms > 0 else 0.0
    versus = f"version {champion_version}'s {cp_rms:.3f} nT"
    if not gain > margin:
        return decided(
            False,
            "margin",
            f"held-out {metric} {ch_rms:.3f} nT does not beat {versus} in service{where} "
            f"(gain {100 * gain:.2f} %, needs > {100 * margin:g} %)",
            cp_rms,
            gain,
        )
    n = min(n_chunks, len(challenger_sq_nt2))
    p = _chunk_p_value(challenger_sq_nt2, champion_sq_nt2, n)
    if p < alpha:
        return decided(
            True,
            "margin and significance",
            f"held-out {metric} {ch_rms:.3f} nT beats {versus}{where} "
            f"(gain {100 * gain:.2f} % > {100 * margin:g} %, p = {p:.2g} < {alpha:g})",
            cp_rms,
            gain,
            p,
        )
    return decided(
        False,
        "significance",
        f"held-out {metric} {ch_rms:.3f} nT does not beat {versus} in service{where} "
        f"significantly (gain {100 * gain:.2f} %, p = {p:.2g} >= {alpha:g} over {n} chunks)",
        cp_rms,
        gain,
        p,
    )


# ---------------------------------------------------------------------------------------------
# A retraining step


@dataclass(frozen=True)
class Retraining:
    """What :func:`retrain` decided: the challenger's document and the promotion."""

    document: dict[str, Any]
    promotion: Promotion
    holdout_start_utc_s: float
    holdout_end_utc_s: float
    n_holdout: int
    #: Rows left out before the fit, by reason (``"outlier"``: :func:`gross_outlier_free`).
    excluded: dict[str, int] = field(default_factory=dict)


def retrain(
    telemetry: Telemetry,
    *,
    orbit: Any,
    champion: dict[str, Any] | None,
    champion_version: int | None = None,
    method: str,
    field: str,
    attitude_frame: str,
    holdout_fraction: float,
    rng: np.random.Generator,
    fit: FitFunction | None = None,
    margin: float = PROMOTE_MARGIN,
    alpha: float = PROMOTE_ALPHA,
) -> Retraining:
    """Fit a challenger on the earlier rows, score challenger and champion on the same later rows
    (through their full calibrations) and decide the promotion.

    Parameters
    ----------
    telemetry
        The rows to use (already chosen: :func:`training_window`, :func:`usable_rows`).
    champion
        The document in service, or None.
    fit
        ``fit(telemetry, *, orbit, method, field, attitude_frame, holdout_fraction, rng)`` → a
        document (default :func:`fit_document`; tests inject their own).

    Raises
    ------
    NotEnoughDataError
        ``holdout_fraction`` leaves no held-out rows.
    """
    from orbitcal.timescales import utc_s_to_iso

    tel = telemetry.sort_by_time()
    truth_all, _ = fit_data_for_telemetry(
        tel, orbit=orbit, field=field, attitude_frame=attitude_frame
    )
    assert truth_all.b_ref_mag_nt is not None
    keep = gross_outlier_free(truth_all.b_raw_nt, truth_all.b_ref_mag_nt)
    excluded = {} if keep.all() else {"outlier": int(np.count_nonzero(~keep))}
    if excluded:
        tel, truth_all = tel.select(keep), truth_all.subset(keep)
    _train, hold = later_block_split(tel.t_utc_s, holdout_fraction)
    if not np.any(hold):
        raise NotEnoughDataError(
            "holdout_fraction leaves no held-out samples to compare calibrations on"
        )
    document = (fit or fit_document)(
        tel,
        orbit=orbit,
        method=method,
        field=field,
        attitude_frame=attitude_frame,
        holdout_fraction=holdout_fraction,
        rng=rng,
    )
    truth = truth_all.subset(hold)
    doc_method = str(document.get("method", method))
    vector = METHODS[doc_method].vector if doc_method in METHODS else True
    metric = primary_key(vector=vector and truth.b_ref_body_nt is not None)

    def squared(doc: dict[str, Any]) -> FloatArray:
        _b, vec, scalar = residuals(doc, truth)
        if metric == "rms_nt":
            assert vec is not None
            return np.mean(vec**2, axis=1)
        return scalar**2

    t_hold = tel.t_utc_s[hold]
    span = utc_s_to_iso([float(t_hold[0]), float(t_hold[-1])])
    champion_sq, problem = None, None
    if champion is not None:
        try:
            champion_sq = squared(champion)
        except ValueError as exc:  # e.g. a housekeeping column the new data lack
            problem = str(exc)
    promotion = decide_promotion(
        squared(document),
        champion_sq,
        metric=metric,
        champion_version=champion_version,
        span=f"{span[0]}..{span[1]}",
        margin=margin,
        alpha=alpha,
        champion_problem=problem,
    )
    return Retraining(
        document,
        promotion,
        float(t_hold[0]),
        float(t_hold[-1]),
        int(np.count_nonzero(hold)),
        excluded,
    )


# ---------------------------------------------------------------------------------------------
# Diagnosis


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
