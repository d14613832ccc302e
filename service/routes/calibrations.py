"""Calibrations: retrain now, the version in service, every version, residuals, diagnosis."""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import re
import time
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import orjson
import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from starlette.datastructures import QueryParams
from starlette.types import ASGIApp, Receive, Scope, Send

from orbitcal import pipeline
from orbitcal.errors import BadInputError, ConflictError
from orbitcal.metrics import norm_rms_nt, rms_nt
from service.auth import Principal, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft, iso
from service.diagnosis_cache import DiagnosisCache
from service.jobs import create_job
from service.numeric import ASCII_INTEGER
from service.routes.exports import FormatQuery, HkQuery, NamesQuery, export_response
from service.schemas import (
    CalibrationDocument,
    CalibrationVersionPublic,
    ErrorPublic,
    JobAccepted,
    RetrainIn,
)
from service.storage import Calibration, Job, hash_key, read_tx, read_window

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.result import Report

__all__ = ["CalibrationFastPath", "ServedCalibration", "answer_key", "router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["calibrations"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
}


class RetrainConflictError(ConflictError):
    """A retraining with other parameters is queued or running for this spacecraft (409)."""

    def __init__(self, spacecraft_id: str, job_id: str, field: str, running: Any, asked: Any):
        self.field = field
        self.body_extra = {"job_id": job_id}
        super().__init__(
            f"a retraining of {spacecraft_id!r} with {field}={running!r} is already "
            f"queued or running as job {job_id}; {field}={asked!r} can be asked for once it "
            f"has finished (GET /v1/jobs/{job_id})"
        )


def _check_method(method: str) -> None:
    """422 now (not a job that fails later) for a method no calibrator is registered under."""
    from orbitcal.calibrate import METHODS

    if method not in METHODS:
        raise BadInputError(
            f"unknown calibration method {method!r}; known: {', '.join(METHODS)}",
            field="method",
        )


@router.post(
    "/{spacecraft_id}/calibrations",
    status_code=202,
    responses={**_ERRORS, 409: {"model": ErrorPublic}, 422: {"model": ErrorPublic}},
)
def retrain_now(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("ingest")],
    body: RetrainIn | None = None,
) -> JobAccepted:
    """Queue a retraining; 202 with the job id.

    While a retraining of the spacecraft is queued or running, a request that names no
    parameters, or the same ones, answers that job's id (202); a request naming a different
    ``method``, ``window_s`` or ``seed`` is a 409 naming the running job. An unknown method is a
    422 at once.
    """
    params = {} if body is None else body.model_dump(exclude_none=True)
    if "method" in params:
        _check_method(params["method"])
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
    job_id, created = create_job(engine, settings, sc.pk, trigger="api", overrides=params)
    if created:
        request.app.state.runner.submit(job_id)
        return JobAccepted(job_id=job_id)
    with read_tx(engine) as conn:
        running = conn.execute(sa.select(Job.params).where(Job.id == job_id)).scalar_one()
    for name, asked in params.items():
        if running.get(name) != asked:
            raise RetrainConflictError(spacecraft_id, job_id, name, running.get(name), asked)
    return JobAccepted(job_id=job_id)


@dataclass(frozen=True)
class ServedCalibration:
    """One spacecraft's answer to ``GET .../calibration``, serialized once per version."""

    body: bytes | None  # the document as JSON bytes; None: no calibration in service
    version: int | None
    etag: str | None
    expires_at: float  # time.monotonic() after which the database is asked again
    #: the 200 answer's headers, built once per version (the fast path sends them as they are)
    head: tuple[tuple[bytes, bytes], ...] = ()


def _served_document(engine: Any, spacecraft_id: str) -> tuple[int, dict[str, Any]] | None:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        row = conn.execute(
            sa.select(Calibration.version, Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).first()
    return None if row is None else (int(row.version), row.document)


def _served(
    previous: ServedCalibration | None, found: tuple[int, dict[str, Any]] | None, ttl_s: float
) -> ServedCalibration:
    expires_at = time.monotonic() + ttl_s
    if found is None:
        return ServedCalibration(None, None, None, expires_at)
    version, document = found
    if previous is not None and previous.version == version and previous.body is not None:
        # same version: no new serialization
        return ServedCalibration(previous.body, version, previous.etag, expires_at, previous.head)
    body = orjson.dumps(document)
    etag = f'"v{version}-{hashlib.sha256(body).hexdigest()[:16]}"'
    head = (
        (b"etag", etag.encode("latin-1")),
        (b"cache-control", b"no-cache"),
        (b"content-length", str(len(body)).encode()),
        (b"content-type", b"application/json"),
    )
    return ServedCalibration(body, version, etag, expires_at, head)


def _etag_matches(if_none_match: str | None, etag: str) -> bool:
    if not if_none_match:
        return False
    tags = {t.strip().removeprefix("W/") for t in if_none_match.split(",")}
    return etag in tags or "*" in tags


def _calibration_response(served: ServedCalibration, if_none_match: str | None) -> Response:
    assert served.body is not None and served.etag is not None
    headers = {"ETag": served.etag, "Cache-Control": "no-cache"}
    if _etag_matches(if_none_match, served.etag):
        return Response(status_code=304, headers=headers)
    return Response(content=served.body, media_type="application/json", headers=headers)


@router.get(
    "/{spacecraft_id}/calibration",
    response_model=CalibrationDocument,
    responses={**_ERRORS, 304: {"description": "not modified (If-None-Match matched the ETag)"}},
)
async def calibration_in_service(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("read")],
    format: FormatQuery = None,
    raw_names: NamesQuery = None,
    cal_names: NamesQuery = None,
    hk_names: HkQuery = None,
) -> Response:
    """The calibration in service (CONTRACT section 4); 404 before the first. With
    ``?format=F`` its export (section 7, ``routes/exports.py``).

    The answer carries an ``ETag`` (the version and a digest of the document); a request whose
    ``If-None-Match`` names it gets 304 without a body. Answers are served from memory for
    ``ORBITCAL_READ_CACHE_S`` (default 1 s) per spacecraft, then the database is asked which
    version is in service; a promotion in this process shows at once.
    """
    cache: dict[str, ServedCalibration] = request.app.state.calibration_cache
    hit = cache.get(spacecraft_id)
    if hit is None or hit.expires_at <= time.monotonic():
        # single flight: concurrent misses for one spacecraft wait for one database read
        locks: dict[str, asyncio.Lock] = request.app.state.calibration_locks
        lock = locks.setdefault(spacecraft_id, asyncio.Lock())
        async with lock:
            hit = cache.get(spacecraft_id)
            if hit is None or hit.expires_at <= time.monotonic():
                found = await run_in_threadpool(_served_document, engine, spacecraft_id)
                if len(cache) > 100_000:
                    cache.clear()
                    locks.clear()
                hit = _served(hit, found, settings.read_cache_s)
                cache[spacecraft_id] = hit
    if hit.body is None:
        raise HTTPException(
            status_code=404, detail=f"spacecraft {spacecraft_id!r} has no calibration in service"
        )
    if format is not None:
        doc = orjson.loads(hit.body)
        return await run_in_threadpool(
            lambda: export_response(
                doc,
                format,
                raw_names,
                cal_names,
                hk_names,
                engine=engine,
                spacecraft_id=spacecraft_id,
            )
        )
    return _calibration_response(hit, request.headers.get("if-none-match"))


_CALIBRATION_PATH = re.compile(r"/v1/spacecraft/([^/]+)/calibration")


class CalibrationFastPath:
    """ASGI shortcut for ``GET /v1/spacecraft/{id}/calibration`` when everything is in memory.

    Serves the request straight from the route's cache when the answer is certain without the
    database: the key is the bootstrap admin key or sits unexpired in the key cache of
    ``service.auth.principal`` with a scope that allows reading the spacecraft, and the cached
    document has not expired. Everything else — a missing, unknown or uncached key, a missing
    scope, an expired or absent cache entry, 404s — goes to the route, which answers as always
    and refills the caches. So the shortcut changes no answer, only what it costs: no routing,
    no dependency injection, no thread-pool hop, no ORM and no serialization on the hot path.
    """

    def __init__(self, app: ASGIApp, state: Any) -> None:
        self.app = app
        self.state = state

    def _allowed(self, scope: Scope, spacecraft_id: str) -> bool:
        settings = self.state.settings
        if not settings.auth:
            return True
        key = next((v for k, v in scope["headers"] if k == b"x-api-key"), None)
        if not key:
            return False
        try:
            presented = hash_key(key.decode("latin-1"))
        except UnicodeError:  # pragma: no cover - latin-1 decodes every byte
            return False
        admin_hash: str | None = self.state.admin_key_hash
        if admin_hash is not None and hmac.compare_digest(presented, admin_hash):
            return True
        hit = self.state.key_cache.get(presented)
        if hit is None or hit[0] is None or hit[1] <= time.monotonic():
            return False
        return bool(hit[0].allows("read", spacecraft_id))

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "GET":
            match = _CALIBRATION_PATH.fullmatch(scope["path"])
            # The route's own query parser (Starlette's, percent-decoding, ``?format`` without
            # ``=``): any ``format`` at all goes to the route (issue 44).
            if match is not None and "format" not in QueryParams(scope.get("query_string", b"")):
                spacecraft_id = match.group(1)
                hit: ServedCalibration | None = self.state.calibration_cache.get(spacecraft_id)
                if (
                    hit is not None
                    and hit.body is not None
                    and hit.expires_at > time.monotonic()
                    and self._allowed(scope, spacecraft_id)
                ):
                    inm = next((v for k, v in scope["headers"] if k == b"if-none-match"), None)
                    if inm is not None:
                        response = _calibration_response(hit, inm.decode("latin-1"))
                        await response(scope, receive, send)
                        return
                    # the answer _calibration_response gives, without building a Response
                    await send(
                        {"type": "http.response.start", "status": 200, "headers": list(hit.head)}
                    )
                    await send({"type": "http.response.body", "body": hit.body})
                    return
        await self.app(scope, receive, send)


@router.get("/{spacecraft_id}/calibrations", responses=_ERRORS)
def calibration_versions(
    spacecraft_id: str, engine: EngineDep, _who: Annotated[Principal, require_scope("read")]
) -> list[CalibrationVersionPublic]:
    """Every version, newest first, with status (in_service | rejected | superseded) and reason."""
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        rows = conn.execute(
            sa.select(Calibration)
            .where(Calibration.spacecraft_pk == sc.pk)
            .order_by(Calibration.version.desc())
        ).all()
    return [
        CalibrationVersionPublic(
            version=c.version,
            status=c.status,  # type: ignore[arg-type]
            reason=c.reason,
            created_at=iso(c.created_at),
            holdout_rms_nt=c.holdout_rms_nt,
            job_id=c.job_id,
            provenance=c.provenance,
            document=c.document,
        )
        for c in rows
    ]


def _recent_telemetry(engine: Any, spacecraft_id: str, settings: Any) -> tuple[Any, Any, Any]:
    """The spacecraft, its recent window (chosen as for retraining: outliers in time and
    quarantined rows left out; rows without attitude left out when some have it) and the
    calibration document in service."""
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        window, samples = read_window(
            conn,
            sc.pk,
            window_s=settings.window_s,
            min_samples=settings.min_samples,
            now_utc_s=time.time(),
        )
        if window.end_utc_s is None:
            raise HTTPException(status_code=404, detail=f"spacecraft {spacecraft_id!r} has no data")
        doc = conn.execute(
            sa.select(Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).scalar_one_or_none()
    attitude = samples.has("q_w", "q_x", "q_y", "q_z")
    if attitude.any():
        samples = samples.select(attitude)
    return sc, samples.to_telemetry(), doc


@router.get("/{spacecraft_id}/residuals", responses=_ERRORS)
def residuals(
    spacecraft_id: str,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("read")],
    max_points: Annotated[int, Query(ge=10, le=20000), ASCII_INTEGER] = 1000,
) -> dict[str, Any]:
    """Residual of the calibration in service against the reference field on the recent window,
    through its full model (network and housekeeping terms included): per axis
    (``residual_xyz_nt``) and ``|b_cal - b_ref|`` (``residual_nt``) [nT] vs time.

    ``rms_nt`` (per component) and ``norm_rms_nt`` (of the vector magnitude) follow
    ``orbitcal.metrics`` over **every** sample of the window (``n_samples``), so they do not depend
    on ``max_points``, which thins only the series returned for the plot.
    """
    sc, tel, doc = _recent_telemetry(engine, spacecraft_id, settings)
    if doc is None:
        raise HTTPException(status_code=404, detail="no calibration in service")
    if tel.q_wxyz is None:
        raise BadInputError(
            "residuals need attitude quaternions (q_w, q_x, q_y, q_z) on the samples of the window",
            field="q_w",
        )
    truth, _ = pipeline.fit_data_for_telemetry(
        tel,
        orbit=pipeline.orbit_from(sc.tle, sc.omm),
        attitude_frame=sc.attitude_frame,
        field=str(doc.get("reference_field", settings.reference_field)),
    )
    _b_cal, res, _scalar = pipeline.residuals(doc, truth)
    assert res is not None
    n = tel.t_utc_s.shape[0]
    idx = np.unique(np.linspace(0, n - 1, min(n, max_points)).astype(int))
    shown = res[idx]
    return {
        "spacecraft": sc.id,
        "version": doc.get("version"),
        "method": doc.get("method"),
        "n_samples": int(n),
        "t_utc_s": tel.t_utc_s[idx].tolist(),
        "residual_nt": np.linalg.norm(shown, axis=1).tolist(),
        "residual_xyz_nt": shown.tolist(),
        "rms_nt": rms_nt(res),
        "norm_rms_nt": norm_rms_nt(res),
    }


def answer_key(sc: Any, doc: dict[str, Any] | None, settings: Any) -> tuple[Any, ...]:
    """Everything that changes a diagnosis of this spacecraft: the samples (their revision,
    bumped on ingest, delete and quarantine), the orbit, the attitude frame, the calibration in
    service, the method and reference field, the window and the code version."""
    from service.jobs import code_version

    orbit = hashlib.sha256(orjson.dumps([sc.tle, sc.omm], option=orjson.OPT_SORT_KEYS))
    return (
        int(sc.data_revision),
        orbit.hexdigest(),
        sc.attitude_frame,
        None if doc is None else doc.get("version"),
        settings.method,
        settings.reference_field,
        float(settings.window_s),
        code_version(),
    )


def _compute_diagnosis(app: Any, spacecraft_id: str, prior: bool) -> Report:
    settings = app.state.settings
    sc, tel, doc = _recent_telemetry(app.state.engine, spacecraft_id, settings)
    if prior and doc is None:
        raise BadInputError(
            f"prior=true needs a calibration in service and {spacecraft_id!r} has none yet",
            field="prior",
        )
    if tel.q_wxyz is None:
        raise BadInputError(
            "the diagnosis needs attitude quaternions (q_w, q_x, q_y, q_z) on the samples of "
            "the window",
            field="q_w",
        )
    report = pipeline.diagnose(
        tel,
        orbit=pipeline.orbit_from(sc.tle, sc.omm),
        attitude_frame=sc.attitude_frame,
        field=settings.reference_field,
        prior_document=doc if prior else None,
    )
    # keyed on the snapshot the report was computed from (read in one transaction)
    app.state.diagnoses.store((spacecraft_id, prior), answer_key(sc, doc, settings), report)
    return report


def _current_key(engine: Any, spacecraft_id: str, settings: Any) -> tuple[Any, ...]:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        doc = conn.execute(
            sa.select(Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).scalar_one_or_none()
    return answer_key(sc, doc, settings)


@router.get(
    "/{spacecraft_id}/diagnosis",
    responses={**_ERRORS, 422: {"model": ErrorPublic}},
)
async def diagnosis(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    cached: Annotated[
        bool,
        Query(
            description="answer the latest report computed so far at once (404 if none) instead "
            "of computing one on the current data"
        ),
    ] = False,
    prior: Annotated[
        bool,
        Query(
            description="take the calibration in service as a prior on the 12 parameters (for "
            "short windows, e.g. a storm, where a free scale factor absorbs the external field)"
        ),
    ] = False,
) -> dict[str, Any]:
    """A diagnosis report (CONTRACT section 5) on the stored telemetry's recent window.

    Reports are computed in a background thread (one computation per spacecraft at a time) and
    kept per spacecraft until anything they depend on changes (samples, orbit, calibration in
    service, method, reference field, window, code version: ``answer_key``). Without ``cached``
    the call waits for a report on the current data (minutes for a day of data); with
    ``cached=true`` it answers the latest report at once. With ``prior=true`` the calibration in
    service is the prior of every fit (``baseline.calibration_prior`` names its version); 422
    when none is in service.
    """
    app = request.app
    diagnoses: DiagnosisCache = app.state.diagnoses
    current = await run_in_threadpool(_current_key, engine, spacecraft_id, app.state.settings)
    key = (spacecraft_id, prior)
    hit = diagnoses.latest(key)
    if hit is not None and (cached or hit[0] == current):
        return hit[1].to_json()
    if cached:
        state = "one is being computed" if diagnoses.computing(key) else "none asked for"
        raise HTTPException(
            status_code=404,
            detail=f"no diagnosis of {spacecraft_id!r} yet ({state}); "
            "GET without cached=true computes one",
        )
    fut = diagnoses.future(key, partial(_compute_diagnosis, app, spacecraft_id, prior))
    report = await asyncio.wrap_future(fut)  # the library's typed errors: one handler, app.py
    return report.to_json()
