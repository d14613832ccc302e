"""Calibrations exported for ground tools over HTTP (CONTRACT sections 3 and 7).

``GET /v1/spacecraft/{id}/calibration?format=F`` (the version in service, answered through
:func:`export_response` from ``routes/calibrations.py``) and
``GET /v1/spacecraft/{id}/calibrations/{version}[?format=F]`` (any stored version). ``F`` as in
``orbitcal export``; ``yamcs-push`` answers the ``parameters:batchSet`` body a client would send
to Yamcs (a GET changes nothing anywhere). Unknown formats and bad names are 422.

Formats that carry less than the whole model (the affine part of a network in ``xtce`` and
``c-header``, the diagonal in ``polynomial``) state their held-out RMS measured on the samples
the version's own retraining held out (``provenance.comparison.holdout_start..end``, read back
from storage), computed once per version and spacecraft.
"""

from __future__ import annotations

import logging
from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Query, Response
from fastapi.concurrency import run_in_threadpool

from orbitcal.errors import OrbitcalError
from orbitcal.export import (
    DEFAULT_CAL_NAMES,
    DEFAULT_RAW_NAMES,
    ExportOptions,
    HeldOutLoss,
    calibration_form,
    document_sha256,
    export,
    held_out_loss,
    parse_hk_names,
    parse_names,
    product_info,
)
from orbitcal.export.product import is_exact_affine
from service.auth import Principal, require_scope
from service.deps import EngineDep, get_spacecraft
from service.numeric import VersionPath
from service.schemas import ErrorPublic
from service.storage import Calibration, read_samples, read_tx

log = logging.getLogger("orbitcal.service.exports")

__all__ = ["FormatQuery", "export_response", "router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["calibrations"])

FormatQuery = Annotated[
    str | None,
    Query(
        description="export format (CONTRACT section 7): json, xtce, yamcs-push (the batchSet "
        "body), yamcs-instance (zip), cosmos (zip), c-header, polynomial"
    ),
]
NamesQuery = Annotated[str | None, Query(description="three parameter names X,Y,Z")]
HkQuery = Annotated[
    str | None, Query(description="housekeeping parameters COLUMN=NAME,... (e.g. temperature=T)")
]


_LOSSES: dict[tuple[str, str], HeldOutLoss | None] = {}


def _version_loss(engine: Any, spacecraft_id: str, doc: dict[str, Any]) -> HeldOutLoss | None:
    """Held-out RMS of the reduced forms on the samples the version's retraining held out;
    ``None`` (the file then says "not measured") when they cannot be read back."""
    from orbitcal.pipeline import orbit_from
    from orbitcal.timescales import parse_time_values

    key = (spacecraft_id, document_sha256(doc))
    if key in _LOSSES:
        return _LOSSES[key]
    loss = None
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        prov = conn.execute(
            sa.select(Calibration.provenance).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.version == doc.get("version")
            )
        ).scalar_one_or_none()
        span = ((prov or {}).get("comparison") or {}) if isinstance(prov, dict) else {}
        start, end = span.get("holdout_start"), span.get("holdout_end")
        samples = None
        if start and end:
            t, errors = parse_time_values([start, end])
            if not errors:
                samples = read_samples(conn, sc.pk, start_utc_s=float(t[0]), end_utc_s=float(t[1]))
    if samples is not None and len(samples):
        attitude = samples.has("q_w", "q_x", "q_y", "q_z")
        if attitude.any():
            samples = samples.select(attitude)
        try:
            loss = held_out_loss(
                doc,
                samples.to_telemetry(),
                orbit=orbit_from(sc.tle, sc.omm),
                attitude_frame=sc.attitude_frame,
                all_held_out=f"the {len(samples)} samples version {doc.get('version')}'s "
                f"retraining held out ({start} .. {end})",
            )
        except OrbitcalError as exc:
            log.warning("held-out loss not measured", extra={"reason": str(exc)})
    if len(_LOSSES) > 1000:
        _LOSSES.clear()
    _LOSSES[key] = loss
    return loss


def export_response(
    doc: dict[str, Any],
    fmt: str,
    raw_names: str | None = None,
    cal_names: str | None = None,
    hk_names: str | None = None,
    *,
    engine: Any = None,
    spacecraft_id: str | None = None,
) -> Response:
    """The document exported as ``fmt``, with its digest in ``X-Orbitcal-Document-SHA256``.

    With ``engine`` and ``spacecraft_id`` the reduced forms state their held-out loss
    (:func:`_version_loss`)."""
    loss = None
    reduced = fmt == "polynomial" or (
        fmt in ("xtce", "yamcs-instance", "c-header") and not is_exact_affine(calibration_form(doc))
    )
    if reduced and engine is not None and spacecraft_id is not None:
        loss = _version_loss(engine, spacecraft_id, doc)
    options = ExportOptions(
        format="json" if fmt == "yamcs-push" else fmt,
        raw_names=parse_names(raw_names, DEFAULT_RAW_NAMES, "raw_names"),
        cal_names=parse_names(cal_names, DEFAULT_CAL_NAMES, "cal_names"),
        hk_names=parse_hk_names(hk_names, "hk_names"),
        loss=loss,
    )
    headers = {"X-Orbitcal-Document-SHA256": document_sha256(doc)}
    if fmt == "yamcs-push":
        import orjson

        from orbitcal.export.yamcs_push import set_request

        opts = ExportOptions(
            format="yamcs-push",
            raw_names=options.raw_names,
            cal_names=options.cal_names,
            hk_names=options.hk_names,
        )
        from orbitcal.export.api import check_names

        check_names(calibration_form(doc), product_info(doc), opts)  # as export() does
        body = set_request(calibration_form(doc), product_info(doc), opts)
        return Response(
            orjson.dumps(body, option=orjson.OPT_INDENT_2),
            media_type="application/json",
            headers=headers,
        )
    result = export(doc, options)
    if fmt != "json":
        headers["Content-Disposition"] = f'attachment; filename="{result.filename}"'
    return Response(result.body(), media_type=result.media_type, headers=headers)


@router.get(
    "/{spacecraft_id}/calibrations/{version}",
    responses={
        401: {"model": ErrorPublic},
        403: {"model": ErrorPublic},
        404: {"model": ErrorPublic},
        422: {"model": ErrorPublic},
    },
)
async def calibration_version(
    spacecraft_id: str,
    version: VersionPath,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    format: FormatQuery = None,
    raw_names: NamesQuery = None,
    cal_names: NamesQuery = None,
    hk_names: HkQuery = None,
) -> Response:
    """One stored version's document (CONTRACT section 4), or its export with ``?format=F``."""

    def load() -> dict[str, Any] | None:
        with read_tx(engine) as conn:
            sc = get_spacecraft(conn, spacecraft_id)
            doc: dict[str, Any] | None = conn.execute(
                sa.select(Calibration.document).where(
                    Calibration.spacecraft_pk == sc.pk, Calibration.version == version
                )
            ).scalar_one_or_none()
        return doc

    doc = await run_in_threadpool(load)
    if doc is None:
        raise HTTPException(
            status_code=404, detail=f"spacecraft {spacecraft_id!r} has no version {version}"
        )
    return await run_in_threadpool(
        lambda: export_response(
            doc,
            "json" if format is None else format,  # ?format= is a 422, as on /calibration
            raw_names,
            cal_names,
            hk_names,
            engine=engine,
            spacecraft_id=spacecraft_id,
        )
    )
