"""Calibrations exported for ground tools over HTTP (CONTRACT sections 3 and 7).

``GET /v1/spacecraft/{id}/calibration?format=F`` (the version in service, answered through
:func:`export_response` from ``routes/calibrations.py``) and
``GET /v1/spacecraft/{id}/calibrations/{version}[?format=F]`` (any stored version). ``F`` as in
``orbitcal export``; ``yamcs-push`` answers the ``parameters:batchSet`` body a client would send
to Yamcs (a GET changes nothing anywhere). Unknown formats and bad names are 422.
"""

from __future__ import annotations

from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Query, Response
from fastapi.concurrency import run_in_threadpool

from orbitcal.export import (
    DEFAULT_CAL_NAMES,
    DEFAULT_RAW_NAMES,
    ExportOptions,
    calibration_form,
    document_sha256,
    export,
    parse_hk_names,
    parse_names,
    product_info,
)
from service.auth import Principal, require_scope
from service.deps import EngineDep, get_spacecraft
from service.schemas import ErrorPublic
from service.storage import Calibration, read_tx

__all__ = ["FormatQuery", "export_response", "router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["calibrations"])

FormatQuery = Annotated[
    str | None,
    Query(
        description="export format (CONTRACT section 7): json, xtce, yamcs-push (the batchSet "
        "body), cosmos (zip), c-header, polynomial"
    ),
]
NamesQuery = Annotated[str | None, Query(description="three parameter names X,Y,Z")]
HkQuery = Annotated[
    str | None, Query(description="housekeeping parameters COLUMN=NAME,... (e.g. temperature=T)")
]


def export_response(
    doc: dict[str, Any],
    fmt: str,
    raw_names: str | None = None,
    cal_names: str | None = None,
    hk_names: str | None = None,
) -> Response:
    """The document exported as ``fmt``, with its digest in ``X-Orbitcal-Document-SHA256``."""
    options = ExportOptions(
        format="json" if fmt == "yamcs-push" else fmt,
        raw_names=parse_names(raw_names, DEFAULT_RAW_NAMES, "raw_names"),
        cal_names=parse_names(cal_names, DEFAULT_CAL_NAMES, "cal_names"),
        hk_names=parse_hk_names(hk_names, "hk_names"),
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
    version: int,
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
        export_response, doc, format or "json", raw_names, cal_names, hk_names
    )
