"""The diagnosis pipeline: telemetry + orbit -> truth -> attribution -> CONTRACT section-5 report.

:func:`diagnosis_data` turns a validated :class:`orbitcal.telemetry.Telemetry` into the plain
arrays of :class:`~orbitcal.diagnose.effects.DiagnosisData` (reference field in body axes through
:mod:`orbitcal.truth`, ITRS->body rotations through :mod:`orbitcal.frames`, Sun and eclipse through
:mod:`orbitcal.sun`, the RC index and a crustal model through :mod:`orbitcal.field`);
:func:`diagnose` runs the attribution, the where-analysis and the seed-003 learned model and
returns the report.
"""

from __future__ import annotations

import warnings
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.attribution import Attribution, attribute
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.diagnose.prior import CalibrationPrior
from orbitcal.diagnose.report import build_report
from orbitcal.diagnose.track import along_track
from orbitcal.diagnose.where import where_analysis
from orbitcal.errors import BadInputError

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.orbit import Propagator
    from orbitcal.telemetry import Telemetry

__all__ = [
    "DEFAULT_CRUST_MODEL",
    "diagnose",
    "diagnose_data",
    "diagnose_parts",
    "diagnosis_data",
    "rotation_itrs_to_body",
]


#: Crustal model used as the crustal_field candidate (Olsen et al. 2017).
DEFAULT_CRUST_MODEL = "LCS-1"


def rotation_itrs_to_body(
    t_utc_s: FloatArray, q_wxyz: FloatArray, *, attitude_frame: str = "GCRS"
) -> FloatArray:
    """Matrices ``R`` with ``v_body = R @ v_itrs``, shape (N, 3, 3).

    Parameters
    ----------
    t_utc_s : ndarray, shape (N,)
        POSIX seconds of UTC [s].
    q_wxyz : ndarray, shape (N, 4)
        Body orientation in the attitude frame (CONTRACT section 1 convention).
    attitude_frame : {"GCRS", "ITRS"}
    """
    from orbitcal import frames
    from orbitcal.attitude import quat_wxyz_to_matrix

    frame_to_body = quat_wxyz_to_matrix(q_wxyz)
    frame = attitude_frame.upper()
    if frame == "ITRS":
        return np.asarray(frame_to_body)
    if frame != "GCRS":
        raise ValueError(f"attitude_frame must be GCRS or ITRS, not {attitude_frame!r}")
    gcrs_to_itrs = frames.gcrs_to_itrs_matrix(t_utc_s)
    return np.asarray(np.einsum("nij,nkj->nik", frame_to_body, gcrs_to_itrs))


#: Largest time between the samples at which the crustal model is evaluated [s]; between them
#: the field is interpolated along the track (cubic spline of the ITRS components in time, per
#: contiguous stretch). Its shortest wavelengths at orbit height are hundreds of km: on the
#: one-day 1 Hz Swarm A world (LCS-1 to degree 185, 86,400 samples) a 10 s spacing (76 km)
#: interpolates to 6.5e-5 nT rms and 2.5e-3 nT at worst, against a crustal field of 2.5 nT rms
#: and sensor noise of 0.1 nT and more (``benchmarks/results/diagnose_timing.md``), with a tenth
#: of the evaluations.
CRUST_KNOT_SPACING_S = 10.0


def _field_itrs(name: str, t: FloatArray, r_itrs_km: FloatArray) -> FloatArray:
    from orbitcal import frames
    from orbitcal.field import get_field

    radius, colat, lon = frames.itrs_to_spherical(r_itrs_km)
    b_nec = get_field(name).b_nec_nt(t, radius, colat, lon)
    return np.asarray(frames.nec_to_itrs(b_nec, r_itrs_km))


def _field_body(
    name: str,
    t: FloatArray,
    r_itrs_km: FloatArray,
    rot: FloatArray,
    *,
    knot_spacing_s: float | None = None,
) -> FloatArray | None:
    """The field model ``name`` in body axes at every sample [nT], shape (N, 3).

    With ``knot_spacing_s`` it is evaluated at most that far apart in time and interpolated
    along the track (:func:`orbitcal.diagnose.track.along_track`).
    """
    try:
        if knot_spacing_s is None:
            b_itrs = _field_itrs(name, t, r_itrs_km)
        else:
            b_itrs = along_track(partial(_field_itrs, name), t, r_itrs_km, knot_spacing_s)
    except ValueError as exc:  # FieldRangeError: outside the model's span
        warnings.warn(f"{name} not used as a candidate regressor: {exc}", stacklevel=3)
        return None
    return np.asarray(np.einsum("nij,nj->ni", rot, b_itrs))


def diagnosis_data(
    telemetry: Telemetry,
    *,
    orbit: Propagator | None = None,
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
    crust_model: str | None = DEFAULT_CRUST_MODEL,
    external_model: bool = True,
    calibration_prior: CalibrationPrior | None = None,
) -> DiagnosisData:
    """Build the attribution's arrays from a telemetry table.

    Parameters
    ----------
    telemetry : Telemetry
        Validated table with quaternions (vector residuals need the attitude).
    orbit : Propagator, optional
        Orbit for positions when the table has none (an :class:`orbitcal.orbit.Orbit`).
    field : str
        Reference field (``orbitcal.field`` name), default ``"IGRF-14"``.
    attitude_frame : {"GCRS", "ITRS"}
    crust_model : str or None
        Crustal model offered to the crustal_field candidate; None to skip (saves ~1 s per 2000
        samples at n = 185).
    external_model : bool
        Offer the RC-driven magnetospheric field to the external_field candidate.
    calibration_prior : CalibrationPrior, optional
        The calibration in service (:func:`orbitcal.diagnose.prior.prior_from_document`) as a
        prior on the 12 parameters: needed on short spans where a large external field is nearly
        parallel to the main field (a storm pass) and a free scale factor would absorb it.
    """
    from orbitcal import frames
    from orbitcal.sun import illumination_conical, sun_position_gcrs_km
    from orbitcal.truth import truth_for_telemetry

    if telemetry.q_wxyz is None:
        raise BadInputError(
            "the diagnosis needs attitude quaternions (q_w, q_x, q_y, q_z) to compare vectors",
            field="q_w",
        )
    truth = truth_for_telemetry(telemetry, orbit=orbit, attitude_frame=attitude_frame, field=field)
    t = np.asarray(telemetry.t_utc_s, dtype=float)
    rot = rotation_itrs_to_body(t, np.asarray(telemetry.q_wxyz), attitude_frame=attitude_frame)
    r_itrs = np.asarray(truth.r_itrs_km, dtype=float)
    b_ref_body = np.einsum("nij,nj->ni", rot, truth.b_itrs_nt)

    r_gcrs = frames.itrs_to_gcrs(r_itrs, t)
    sun_gcrs = sun_position_gcrs_km(t)
    illumination = np.asarray(illumination_conical(r_gcrs, sun_gcrs), dtype=float)
    s_gcrs = sun_gcrs - r_gcrs
    s_itrs = frames.gcrs_to_itrs(s_gcrs / np.linalg.norm(s_gcrs, axis=1, keepdims=True), t)
    sun_body = np.einsum("nij,nj->ni", rot, s_itrs)

    names: list[str] = []
    cols: list[FloatArray] = []
    if telemetry.temperature_c is not None:
        names.append("temperature")
        cols.append(np.asarray(telemetry.temperature_c, dtype=float))
    if telemetry.mtq_am2 is not None:
        for k, axis in enumerate("xyz"):
            names.append(f"mtq_{axis}")
            cols.append(np.asarray(telemetry.mtq_am2[:, k], dtype=float))
    for key, values in sorted(telemetry.hk.items()):
        arr = np.asarray(values)
        if arr.dtype.kind in "fiu" and np.all(np.isfinite(arr)):
            names.append(key)
            cols.append(arr.astype(float))
    x_hk = np.column_stack(cols) if cols else np.zeros((0, 0))

    rc_index = None
    b_ext_body = None
    if external_model:
        try:
            from orbitcal.field.external import ring_current_field

            rc_e, rc_i = ring_current_field().rc_nt(t)
            rc_index = np.asarray(rc_e + rc_i, dtype=float)
            b_ext_body = _field_body("RC", t, r_itrs, rot)
        except ValueError as exc:
            warnings.warn(f"RC index not used: {exc}", stacklevel=2)
    b_crust_body = (
        _field_body(crust_model, t, r_itrs, rot, knot_spacing_s=CRUST_KNOT_SPACING_S)
        if crust_model
        else None
    )
    return DiagnosisData(
        t_utc_s=t,
        b_raw_nt=np.asarray(telemetry.b_raw_nt, dtype=float),
        b_ref_body_nt=b_ref_body,
        rot_itrs_to_body=rot,
        r_itrs_km=r_itrs,
        x_hk=x_hk,
        hk_names=tuple(names),
        sunlit=illumination > 0.5,
        sun_body=sun_body,
        rc_index_nt=rc_index,
        b_crust_body_nt=b_crust_body,
        crust_model=crust_model if b_crust_body is not None else None,
        reference_field=truth.field_name,
        illumination=illumination,
        b_ext_body_nt=b_ext_body,
        calibration_prior=calibration_prior,
        positions_measured=telemetry.r_itrs_km is not None,
    )


def diagnose_parts(
    data: DiagnosisData,
    *,
    rng: np.random.Generator | None = None,
    learned: bool = True,
    **attribute_options: Any,
) -> tuple[dict[str, Any], Attribution]:
    """Run the diagnosis on prepared arrays: the section-5 report and the attribution behind it.

    Without a crustal model (``data.b_crust_body_nt`` None) and with ``learned``, the seed-003
    model is first fitted to the calibration residual of the training blocks; if its training-only
    cross-validation keeps a stage, its correction is the crustal_field candidate (``variant``
    ``"learned (seed 003)"``), judged on the held-out blocks like any other.
    """
    # Issue 25: options a short span needs, chosen from the data (orbitcal.diagnose.span_options).
    from orbitcal.diagnose.span_options import choose_options

    attribute_options, chosen = choose_options(data, attribute_options)
    learned_result = None
    if learned and data.b_crust_body_nt is None:
        data, learned_result = _with_learned_crust(data, rng=rng, **attribute_options)
    att = attribute(data, **attribute_options)
    where = where_analysis(data, att.baseline_residual_nt, holdout=att.holdout)
    where_final = (
        where_analysis(data, att.final_residual_nt, holdout=att.holdout) if att.selected else None
    )
    if learned and learned_result is None:
        from orbitcal.diagnose.learned import learned_field_error

        learned_result = learned_field_error(
            data, att.final_residual_nt, train=att.train, holdout=att.holdout, rng=rng
        )
        learned_result["fitted_to"] = "the final model's residual on the training blocks"
    report = build_report(data, att, where, learned=learned_result, where_final=where_final)
    # Issue 25: check the report's claims on the held-out data (orbitcal.diagnose.honesty).
    from orbitcal.diagnose.honesty import review_report

    return review_report(report, data, att, chosen=chosen), att


#: Name of the crustal_field variant the seed-003 model stands for.
LEARNED_CRUST = "learned (seed 003)"


def _with_learned_crust(
    data: DiagnosisData, *, rng: np.random.Generator | None, **attribute_options: Any
) -> tuple[DiagnosisData, dict[str, Any] | None]:
    """The data with the seed-003 correction as crustal model, and the model's summary.

    ``(data, None)`` when the training blocks are too few for attribution; the summary with the
    data unchanged when the model keeps no stage.
    """
    import dataclasses

    from orbitcal.diagnose.attribution import HOLDOUT_BLOCKS, N_BLOCKS, fit_joint, time_blocks
    from orbitcal.diagnose.learned import learned_field_model

    train, holdout, _ = time_blocks(
        data.t_utc_s,
        n_blocks=int(attribute_options.get("n_blocks", N_BLOCKS)),
        holdout_blocks=int(attribute_options.get("holdout_blocks", HOLDOUT_BLOCKS)),
    )
    fit_mask = attribute_options.get("fit_mask")
    if fit_mask is not None:
        train = train & np.asarray(fit_mask, dtype=bool)
    if int(train.sum()) < 30:
        return data, None  # attribute() explains why it cannot run
    base = fit_joint(data, train)
    summary, correction = learned_field_model(
        data, data.b_raw_nt - base.predict_nt(data), train=train, holdout=holdout, rng=rng
    )
    summary["fitted_to"] = "the calibration-only residual of the training blocks"
    if summary["stage_chosen"] == "none":
        return data, summary
    summary["candidate"] = f"crustal_field ({LEARNED_CRUST})"
    replaced = dataclasses.replace(data, b_crust_body_nt=correction, crust_model=LEARNED_CRUST)
    return replaced, summary


def diagnose_data(
    data: DiagnosisData,
    *,
    rng: np.random.Generator | None = None,
    learned: bool = True,
    **attribute_options: Any,
) -> dict[str, Any]:
    """Run the diagnosis on prepared arrays; returns the section-5 report (a JSON-ready dict)."""
    return diagnose_parts(data, rng=rng, learned=learned, **attribute_options)[0]


def diagnose(
    telemetry: Telemetry,
    *,
    orbit: Propagator | None = None,
    field: str = "IGRF-14",
    attitude_frame: str = "GCRS",
    rng: np.random.Generator | None = None,
    calibration_prior: CalibrationPrior | None = None,
) -> dict[str, Any]:
    """Diagnose the sim-to-real gap of a telemetry table (CONTRACT section 5).

    Parameters
    ----------
    telemetry : Telemetry
        Validated table with attitude quaternions; positions from the table or ``orbit``.
    orbit : Propagator, optional
        The spacecraft's orbit (TLE/OMM through :class:`orbitcal.orbit.Orbit`).
    field : str
        Reference field, default ``"IGRF-14"``.
    attitude_frame : {"GCRS", "ITRS"}
    rng : numpy.random.Generator, optional
        Seeds the learned model's network initialisation (default: a fixed seed, so the report is
        reproducible).
    calibration_prior : CalibrationPrior, optional
        The calibration in service as a prior on the 12 parameters (see :func:`diagnosis_data`).

    Returns
    -------
    dict
        ``baseline``, ``verdict``, ``effects`` (ranked), ``where`` and supporting sections.
    """
    data = diagnosis_data(
        telemetry,
        orbit=orbit,
        field=field,
        attitude_frame=attitude_frame,
        calibration_prior=calibration_prior,
    )
    return diagnose_data(data, rng=rng)
