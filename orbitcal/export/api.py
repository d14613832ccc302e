"""The one public entry of the exports: :func:`export` (and :func:`held_out_loss`)."""

from __future__ import annotations

import importlib
import json
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError
from orbitcal.export.options import ExportOptions, ExportResult, HeldOutLoss
from orbitcal.export.product import (
    SCALAR_METHODS,
    AffineForm,
    NetworkForm,
    affine_part,
    calibration_form,
    product_info,
)

if TYPE_CHECKING:
    from orbitcal.telemetry import Telemetry

__all__ = ["check_names", "export", "held_out_loss", "hk_columns"]


def check_names(form: AffineForm | NetworkForm, info: Any, options: ExportOptions) -> None:
    """Refuse (:class:`ExportError`) an export whose names are the same in its target's eyes:
    raw, housekeeping (given or derived from the columns) and calibrated names, and, for XTCE
    and ``yamcs-push``, the ``*_LIN`` outputs and every coefficient parameter it defines
    (:func:`orbitcal.export.names.check_export_names`)."""
    from orbitcal.export.names import check_export_names

    own: list[str] = []
    if options.format in ("xtce", "yamcs-push"):
        from orbitcal.export.xtce import coefficient_values, lin_name

        own = [lin_name(n) for n in options.cal_names]
        own += list(coefficient_values(form, info, options))
    check_export_names(
        raw=options.raw_names,
        cal=options.cal_names,
        hk=[(c, options.hk_parameter(c)) for c in form.hk_names],
        target=options.format,
        own=own,
    )


def hk_columns(form: AffineForm | NetworkForm, telemetry: Telemetry) -> FloatArray | None:
    """The table's housekeeping columns in the order the calibration needs (``None``: none).

    Raises
    ------
    BadInputError
        The table lacks a column the calibration uses.
    """
    if not form.hk_names:
        return None
    x_hk, names = telemetry.regressors()
    missing = [n for n in form.hk_names if n not in names]
    if missing:
        raise BadInputError(
            f"the calibration needs housekeeping columns {', '.join(missing)}, "
            "which the telemetry lacks",
            field=missing[0],
        )
    out: FloatArray = np.asarray(x_hk, dtype=np.float64)[:, [names.index(n) for n in form.hk_names]]
    return out


def held_out_loss(
    doc: dict[str, Any],
    telemetry: Telemetry,
    *,
    orbit: Any = None,
    attitude_frame: str | None = None,
    all_held_out: str | None = None,
) -> HeldOutLoss:
    """Held-out RMS [nT] of the whole calibration and of the reduced forms the exports carry.

    The held-out rows are the later time blocks of ``telemetry`` (the document's
    ``metrics.holdout_fraction``, else :data:`~orbitcal.calibrate.holdout.HOLDOUT_FRACTION`) or,
    with ``all_held_out`` (a sentence saying why, e.g. the span a retraining held out), every row;
    the reference field is the document's. For scalar methods the figure is the scalar one
    (``|b_cal| - |B_ref|``), as for their ``holdout_rms_nt``.
    """
    from orbitcal.calibrate.holdout import HOLDOUT_FRACTION, later_block_split
    from orbitcal.export.evaluate import evaluate
    from orbitcal.export.polynomial import evaluate_diagonal
    from orbitcal.metrics import rms_nt
    from orbitcal.pipeline import fit_data_for_telemetry

    form = calibration_form(doc)
    tel = telemetry.sort_by_time()
    frame = attitude_frame or str((doc.get("model") or {}).get("attitude_frame", "GCRS"))
    fraction = float((doc.get("metrics") or {}).get("holdout_fraction", HOLDOUT_FRACTION))
    data, _ = fit_data_for_telemetry(
        tel, orbit=orbit, field=str(doc["reference_field"]), attitude_frame=frame
    )
    if all_held_out is None:
        _, hold = later_block_split(tel.t_utc_s, fraction)
        where = f"the latest {fraction:.0%} of the table's samples"
    else:
        hold = np.ones(len(tel), dtype=bool)
        where = all_held_out
    if not np.any(hold):
        raise BadInputError("the table has no held-out rows to measure on", field="telemetry")
    raw = np.asarray(tel.b_raw_nt, dtype=np.float64)[hold]
    x = hk_columns(form, tel)
    x = None if x is None else x[hold]
    full = evaluate(form, raw, x)
    aff = evaluate(affine_part(form), raw, x)
    diag = evaluate_diagonal(form, raw)
    scalar = str(doc.get("method")) in SCALAR_METHODS or data.b_ref_body_nt is None
    if scalar:
        assert data.b_ref_mag_nt is not None
        ref_mag = data.b_ref_mag_nt[hold]

        def score(b: FloatArray) -> float:
            return rms_nt(np.linalg.norm(b, axis=1) - ref_mag)

        source = "scalar residual |b_cal| - |B_ref|"
    else:
        assert data.b_ref_body_nt is not None
        ref = data.b_ref_body_nt[hold]

        def score(b: FloatArray) -> float:
            return rms_nt(b, ref)

        source = "vector residual b_cal - b_ref"
    return HeldOutLoss(
        n_samples=int(np.count_nonzero(hold)),
        full_rms_nt=score(full),
        affine_rms_nt=score(aff),
        diagonal_rms_nt=score(diag),
        affine_max_abs_diff_nt=float(np.max(np.abs(aff - full))),
        diagonal_max_abs_diff_nt=float(np.max(np.abs(diag - full))),
        source=f"{source} on {where}, {doc['reference_field']}",
    )


#: The file formats rendered from the calibration form: module and renderer, imported when used.
_RENDERERS = {
    "xtce": ("orbitcal.export.xtce", "render_xtce"),
    "yamcs-instance": ("orbitcal.export.yamcs_instance", "render_yamcs_instance"),
    "cosmos": ("orbitcal.export.cosmos", "render_cosmos"),
    "c-header": ("orbitcal.export.c_header", "render_c_header"),
    "polynomial": ("orbitcal.export.polynomial", "render_polynomial"),
}

_MEDIA = {
    "json": ("application/json", "calibration.json"),
    "xtce": ("application/xml", "magcal_xtce.xml"),
    "yamcs-push": ("application/json", "yamcs_push.json"),
    "yamcs-instance": ("application/zip", "magcal_yamcs_instance.zip"),
    "cosmos": ("application/zip", "magcal_cosmos.zip"),
    "c-header": ("text/x-c", "orbitcal_magcal.h"),
    "polynomial": ("application/json", "magcal_polynomial.json"),
}


def export(doc: dict[str, Any], options: ExportOptions, *, transport: Any = None) -> ExportResult:
    """Export a section-4 document in ``options.format`` (CONTRACT section 7).

    ``yamcs-push`` contacts ``options.yamcs`` (``transport``: an ``httpx`` transport, for
    tests) and returns its report; the other formats only generate.

    Raises
    ------
    DocumentError
        A malformed document.
    ExportError
        Bad options or, for ``yamcs-push``, a failed push.
    """
    info = product_info(doc)
    media, filename = _MEDIA[options.format]
    filename = f"{info.spacecraft}_v{info.version}_{filename}".replace("/", "_")
    if options.format == "json":
        content = (json.dumps(doc, indent=2) + "\n").encode()
        return ExportResult("json", media, info.to_json(), content=content, filename=filename)
    form = calibration_form(doc)
    check_names(form, info, options)
    if options.format in _RENDERERS:
        module, name = _RENDERERS[options.format]
        rendered = getattr(importlib.import_module(module), name)(form, info, options)
        files = options.format in ("cosmos", "yamcs-instance")  # folders; the others one text
        return ExportResult(
            options.format,
            media,
            info.to_json(),
            content=None if files else rendered,
            files=rendered if files else None,
            filename=filename,
        )
    from orbitcal.export.yamcs_push import push_to_yamcs

    report = push_to_yamcs(form, info, options, transport=transport)
    return ExportResult("yamcs-push", media, info.to_json(), report=report, filename=filename)
