"""``POST /v1/spacecraft/{id}/telemetry``: ingest in any supported content type."""

from __future__ import annotations

import time
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool

from orbitcal import ccsds
from orbitcal.telemetry import TelemetryError
from service.auth import Principal, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft
from service.ingest import (
    CCSDS_MEDIA_TYPE,
    MEDIA_TYPES,
    BodyTooLargeError,
    decompress,
    parse_body,
    telemetry_to_rows,
)
from service.schemas import ErrorPublic, IngestResult, RowRejection
from service.storage import insert_samples, read_tx, write_tx

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["telemetry"])

_BODY_DOC: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "description": "A CONTRACT section-1 table, or magnetometer space packets (docs/ccsds.md)",
        "content": {
            "text/csv": {"schema": {"type": "string"}},
            "application/x-ndjson": {"schema": {"type": "string"}},
            "application/json": {"schema": {"type": "array", "items": {"type": "object"}}},
            "application/vnd.apache.parquet": {"schema": {"type": "string", "format": "binary"}},
            CCSDS_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}},
        },
    }
}


_CLOSE = {"Connection": "close"}


async def _read_body(request: Request, limit: int) -> bytes:
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise HTTPException(
            status_code=413,
            detail=f"body of {declared} bytes exceeds {limit}",
            headers=_CLOSE,
        )
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            # Connection: close makes the server drop the connection instead of draining the
            # rest of an endless body (found by tests/reliability/test_bad_inputs.py: 1 GB read).
            raise HTTPException(
                status_code=413, detail=f"body exceeds {limit} bytes", headers=_CLOSE
            )
        chunks.append(chunk)
    return b"".join(chunks)


@router.post(
    "/{spacecraft_id}/telemetry",
    openapi_extra=_BODY_DOC,
    responses={
        400: {"model": ErrorPublic},
        401: {"model": ErrorPublic},
        403: {"model": ErrorPublic},
        404: {"model": ErrorPublic},
        413: {"model": ErrorPublic},
        415: {"model": ErrorPublic},
        503: {"model": ErrorPublic},
    },
)
async def ingest_telemetry(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("ingest")],
    time_scale: Annotated[
        Literal["UTC", "TAI", "GPS"], Query(description="scale of numeric/ISO times in the table")
    ] = "UTC",
    apid: Annotated[
        int | None, Query(ge=0, lt=2048, description="CCSDS: accept only this APID")
    ] = None,
) -> IngestResult:
    """Store a telemetry upload. 200 means the accepted rows are committed (durable).

    Samples whose time is already stored for this spacecraft count as ``duplicates`` and change
    nothing; invalid rows are listed in ``rejected`` and the valid rows of the upload are kept.
    """
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    fmt = MEDIA_TYPES.get(media)
    if fmt is None:
        raise HTTPException(
            status_code=415,
            detail=f"Content-Type {media or '(none)'!r} is not one of {', '.join(MEDIA_TYPES)}",
        )
    body = await _read_body(request, settings.max_body_bytes)
    started = time.perf_counter()

    def work() -> IngestResult:
        with read_tx(engine) as conn:
            get_spacecraft(conn, spacecraft_id)  # 404 before any parsing
        try:
            raw = decompress(
                body, request.headers.get("content-encoding", ""), limit=settings.max_body_bytes
            )
        except BodyTooLargeError as exc:
            raise HTTPException(status_code=413, detail=str(exc)) from None
        except ValueError as exc:
            raise HTTPException(status_code=400, detail=str(exc)) from None
        try:
            parsed = parse_body(raw, fmt=fmt, time_scale=time_scale, apid=apid)
        except (TelemetryError, ccsds.PacketError) as exc:
            raise HTTPException(status_code=400, detail=str(exc)) from None
        with write_tx(engine) as conn:
            sc = get_spacecraft(conn, spacecraft_id)
            rows = telemetry_to_rows(sc.pk, parsed.telemetry)
            accepted = insert_samples(conn, sc.pk, rows)
        return IngestResult(
            accepted=accepted,
            duplicates=len(rows) - accepted,
            rejected=[RowRejection(row=e.row, reason=e.reason) for e in parsed.rejected],
        )

    result = await run_in_threadpool(work)
    metrics = request.app.state.metrics
    metrics.ingest_samples.labels(fmt).inc(result.accepted)
    metrics.ingest_duplicates.labels(fmt).inc(result.duplicates)
    metrics.ingest_rejected.labels(fmt).inc(len(result.rejected))
    metrics.ingest_seconds.labels(fmt).observe(time.perf_counter() - started)
    return result
