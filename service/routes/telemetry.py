"""``POST /v1/spacecraft/{id}/telemetry``: ingest in any supported content type."""

from __future__ import annotations

import logging
import time
from typing import Annotated, Any, Literal, cast

import orjson
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from orbitcal.telemetry import RowError
from service.auth import Principal, check_key_before_commit, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft
from service.ingest import (
    CCSDS_MEDIA_TYPE,
    MEDIA_TYPES,
    check_upload_plausible,
    decompress,
    parse_body,
    telemetry_row_batches,
)
from service.numeric import ASCII_INTEGER
from service.schemas import ErrorPublic, IngestResult
from service.storage import insert_samples, log_upload, read_tx, write_tx

__all__ = ["router"]

log = logging.getLogger("orbitcal.service.telemetry")

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
    response_model=IngestResult,
    openapi_extra=_BODY_DOC,
    responses={
        400: {"model": ErrorPublic},
        401: {"model": ErrorPublic},
        403: {"model": ErrorPublic},
        404: {"model": ErrorPublic},
        413: {"model": ErrorPublic},
        415: {"model": ErrorPublic},
        422: {
            "model": ErrorPublic,
            "description": "no valid row: every row rejected (the list is in `rejected`), or none",
        },
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
        int | None,
        Query(ge=0, lt=2048, description="CCSDS: accept only this APID"),
        ASCII_INTEGER,
    ] = None,
) -> Response:
    """Store a telemetry upload. 200 means the accepted rows are committed (durable).

    Samples whose time is already stored for this spacecraft count as ``duplicates`` and change
    nothing; invalid rows are listed in ``rejected`` and the valid rows of the upload are kept.
    An upload with no valid row is a 422 listing every rejected row; a body beyond a parsing
    limit (rows, columns, nesting, text length, decompressed bytes) is a 413 naming the limit.
    """
    fmt = _upload_format(request)
    body = await _read_body(request, settings.max_body_bytes)
    started = time.perf_counter()

    def work() -> tuple[int, bytes, int, int, int]:
        """(status, JSON body, accepted, duplicates, rejected) of the upload."""
        with read_tx(engine) as conn:
            known = get_spacecraft(conn, spacecraft_id)  # 404 before any parsing
        # The library's typed errors propagate to the one handler in service.app: a damaged
        # compressed stream or an unreadable table is 400, a parsing limit 413 naming it.
        raw = decompress(
            body, request.headers.get("content-encoding", ""), limit=settings.max_body_bytes
        )
        parsed = parse_body(raw, fmt=fmt, time_scale=time_scale, apid=apid)
        implausible = check_upload_plausible(parsed.telemetry, known)  # 422: Tesla, Gauss, µT
        n_rejected = len(parsed.rejected)
        bad = cast(list[tuple[int, str]], parsed.rejected)  # RowError is a (row, reason) tuple
        if len(parsed.telemetry) == 0:
            # Nothing valid to store: say so with the reasons instead of a 200 "accepted 0".
            head = _nothing_stored(parsed.rejected)
            with write_tx(engine) as conn:  # the dashboard's rejected-rows plot
                sc = get_spacecraft(conn, spacecraft_id)
                log_upload(conn, sc.pk, fmt=fmt, accepted=0, duplicates=0, rejected=bad)
            return 422, _result_json(head, parsed.rejected), 0, 0, n_rejected
        with write_tx(engine) as conn:
            sc = get_spacecraft(conn, spacecraft_id)
            accepted = 0
            # One transaction; rows become Python tuples a slice at a time (bounded memory).
            for rows in telemetry_row_batches(sc.pk, parsed.telemetry):
                accepted += insert_samples(conn, sc.pk, rows)
            duplicates = len(parsed.telemetry) - accepted
            log_upload(conn, sc.pk, fmt=fmt, accepted=accepted, duplicates=duplicates, rejected=bad)
            check_key_before_commit(conn, request)  # revoked while the body arrived: roll back
        if accepted:
            _check_health(request, sc.pk, parsed.telemetry if not duplicates else None)
        head = {"accepted": accepted, "duplicates": duplicates}
        if implausible is not None:
            head["warnings"] = [implausible]
        return 200, _result_json(head, parsed.rejected), accepted, duplicates, n_rejected

    status, payload, accepted, duplicates, n_rejected = await run_in_threadpool(work)
    metrics = request.app.state.metrics
    metrics.ingest_samples.labels(fmt).inc(accepted)
    metrics.ingest_duplicates.labels(fmt).inc(duplicates)
    metrics.ingest_rejected.labels(fmt).inc(n_rejected)
    if status == 200:
        metrics.ingest_seconds.labels(fmt).observe(time.perf_counter() - started)
    return Response(payload, status_code=status, media_type="application/json")


def _check_health(request: Request, spacecraft_pk: int, fresh: Any) -> None:
    """After the commit: the new samples go to the health worker (service.health), which scores
    them against the calibration in service off the request path and queues a retraining when it
    is stale. Never fails the upload (its rows are stored)."""
    try:
        request.app.state.health.submit(spacecraft_pk, fresh)
    except Exception:  # the upload is committed; health catches up on the next one
        log.exception("health check after upload failed")


def _upload_format(request: Request) -> str:
    """The table format of the upload's Content-Type; 415 for a type no reader takes."""
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    fmt = MEDIA_TYPES.get(media)
    if fmt is None:
        raise HTTPException(
            status_code=415,
            detail=f"Content-Type {media or '(none)'!r} is not one of {', '.join(MEDIA_TYPES)}",
        )
    return fmt


def _nothing_stored(rejected: list[RowError]) -> dict[str, Any]:
    """The 422 answer's head for an upload without a valid row: why, and the first 100 rows'
    reasons."""
    if rejected:
        first = rejected[0]
        detail = (
            f"every row was rejected ({len(rejected)} rows); nothing was stored. "
            f"First: row {first.row}: {first.reason}"
        )
    else:
        detail = "the upload holds no data rows; nothing was stored"
    return {
        "detail": detail,
        "errors": [{"field": f"row {e.row}", "reason": e.reason} for e in rejected[:100]],
        "accepted": 0,
        "duplicates": 0,
    }


def _result_json(head: dict[str, Any], rejected: list[RowError]) -> bytes:
    """``{**head, "rejected": [{"row": i, "reason": "..."}, ...]}`` as JSON bytes.

    Written directly (each distinct reason encoded once) instead of through one model object per
    row: an upload of 10^6 bad rows cost 1 GB and 30 s of server time through the models.
    """
    encoded: dict[str, bytes] = {}
    items: list[bytes] = []
    for e in rejected:
        reason = encoded.get(e.reason)
        if reason is None:
            reason = encoded[e.reason] = orjson.dumps(e.reason)
        items.append(b'{"row":%d,"reason":%s}' % (e.row, reason))
    return orjson.dumps(head)[:-1] + b',"rejected":[' + b",".join(items) + b"]}"
