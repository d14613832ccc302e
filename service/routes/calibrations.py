"""Calibrations: retrain now, the version in service, every version, residuals, diagnosis."""

from __future__ import annotations

import asyncio
import time
from concurrent.futures import Future
from typing import Annotated, Any

import numpy as np
import orjson
import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from service import science
from service.auth import Principal, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft, iso
from service.jobs import create_job, samples_to_telemetry
from service.schemas import (
    CalibrationDocument,
    CalibrationVersionPublic,
    ErrorPublic,
    JobAccepted,
    RetrainIn,
)
from service.storage import Calibration, read_samples, read_tx

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["calibrations"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
}


@router.post("/{spacecraft_id}/calibrations", status_code=202, responses=_ERRORS)
def retrain_now(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("ingest")],
    body: RetrainIn | None = None,
) -> JobAccepted:
    """Queue a retraining; answers the live job's id if one is already queued or running."""
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
    params = {} if body is None else body.model_dump(exclude_none=True)
    job_id, created = create_job(engine, settings, sc.pk, trigger="api", overrides=params)
    if created:
        request.app.state.runner.submit(job_id)
    return JobAccepted(job_id=job_id)


def _served_document(engine: Any, spacecraft_id: str) -> bytes | None:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        doc = conn.execute(
            sa.select(Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).scalar_one_or_none()
    return None if doc is None else orjson.dumps(doc)


@router.get(
    "/{spacecraft_id}/calibration",
    response_model=CalibrationDocument,
    responses=_ERRORS,
)
async def calibration_in_service(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("read")],
) -> Response:
    """The calibration in service (CONTRACT section 4); 404 before the first.

    Answers are cached per spacecraft for ``ORBITCAL_READ_CACHE_S`` (default 1 s).
    """
    cache: dict[str, tuple[bytes | None, float]] = request.app.state.calibration_cache
    hit = cache.get(spacecraft_id)
    if hit is not None and hit[1] > time.monotonic():
        body = hit[0]
    else:
        # single flight: concurrent misses for one spacecraft wait for one database read
        locks: dict[str, asyncio.Lock] = request.app.state.calibration_locks
        lock = locks.setdefault(spacecraft_id, asyncio.Lock())
        async with lock:
            hit = cache.get(spacecraft_id)
            if hit is not None and hit[1] > time.monotonic():
                body = hit[0]
            else:
                body = await run_in_threadpool(_served_document, engine, spacecraft_id)
                if len(cache) > 100_000:
                    cache.clear()
                    locks.clear()
                cache[spacecraft_id] = (body, time.monotonic() + settings.read_cache_s)
    if body is None:
        raise HTTPException(
            status_code=404, detail=f"spacecraft {spacecraft_id!r} has no calibration in service"
        )
    return Response(content=body, media_type="application/json")


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


def _recent_telemetry(engine: Any, spacecraft_id: str, window_s: float) -> tuple[Any, Any, Any]:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        latest = conn.execute(
            sa.text("SELECT MAX(t_utc_us) FROM samples WHERE spacecraft_pk = :pk"), {"pk": sc.pk}
        ).scalar_one_or_none()
        if latest is None:
            raise HTTPException(status_code=404, detail=f"spacecraft {spacecraft_id!r} has no data")
        samples = read_samples(conn, sc.pk, start_utc_s=latest / 1e6 - window_s)
        doc = conn.execute(
            sa.select(Calibration.document).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).scalar_one_or_none()
    return sc, samples_to_telemetry(samples), doc


@router.get("/{spacecraft_id}/residuals", responses=_ERRORS)
def residuals(
    spacecraft_id: str,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("read")],
    max_points: Annotated[int, Query(ge=10, le=20000)] = 1000,
) -> dict[str, Any]:
    """Residual |b_cal - b_ref| [nT] vs time of the calibration in service on the recent window."""
    sc, tel, doc = _recent_telemetry(engine, spacecraft_id, settings.window_s)
    if doc is None:
        raise HTTPException(status_code=404, detail="no calibration in service")
    n = tel.t_utc_s.shape[0]
    idx = np.unique(np.linspace(0, n - 1, min(n, max_points)).astype(int))
    from service.jobs import _subset

    part = _subset(tel, idx)  # type: ignore[arg-type]
    try:
        b_ref = science.reference_body_nt(
            part,
            orbit=science.load_orbit(sc.tle, sc.omm),
            attitude_frame=sc.attitude_frame,
            field=str(doc.get("reference_field", settings.reference_field)),
        )
    except ValueError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    res = science.apply_linear(doc, part.b_raw_nt) - b_ref
    return {
        "spacecraft": sc.id,
        "version": doc.get("version"),
        "t_utc_s": part.t_utc_s.tolist(),
        "residual_nt": np.linalg.norm(res, axis=1).tolist(),
        "rms_nt": float(np.sqrt(np.mean(res**2))),
    }


def _compute_diagnosis(app: Any, spacecraft_id: str, prior: bool) -> dict[str, Any]:
    settings = app.state.settings
    sc, tel, doc = _recent_telemetry(app.state.engine, spacecraft_id, settings.window_s)
    if prior and doc is None:
        raise ValueError(
            f"prior=true needs a calibration in service and {spacecraft_id!r} has none yet"
        )
    report = science.diagnose(
        tel,
        orbit=science.load_orbit(sc.tle, sc.omm),
        attitude_frame=sc.attitude_frame,
        field=settings.reference_field,
        prior_document=doc if prior else None,
    )
    if prior:
        report["baseline"]["calibration_prior"]["version"] = doc.get("version")
    app.state.diagnosis_cache[(spacecraft_id, prior)] = (int(sc.sample_count), report)
    return report


def _spacecraft(engine: Any, spacecraft_id: str) -> Any:
    with read_tx(engine) as conn:
        return get_spacecraft(conn, spacecraft_id)


def _diagnosis_future(app: Any, spacecraft_id: str, prior: bool) -> Future[dict[str, Any]]:
    """The running computation for this spacecraft, or a new one (one at a time per spacecraft)."""
    running: dict[tuple[str, bool], Future[dict[str, Any]]] = app.state.diagnosis_running
    key = (spacecraft_id, prior)
    with app.state.diagnosis_lock:
        fut = running.get(key)
        if fut is None or fut.done():
            fut = app.state.diagnosis_pool.submit(_compute_diagnosis, app, spacecraft_id, prior)
            running[key] = fut
        return fut


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
    kept per spacecraft until new samples arrive; without ``cached`` the call waits for a report
    on the current data (minutes for a day of data), with ``cached=true`` it answers the latest
    report at once. With ``prior=true`` the calibration in service is the prior of every fit
    (``baseline.calibration_prior`` names its version); 422 when none is in service.
    """
    app = request.app
    sc = await run_in_threadpool(_spacecraft, engine, spacecraft_id)
    key = (spacecraft_id, prior)
    hit = app.state.diagnosis_cache.get(key)
    if hit is not None and (cached or hit[0] == int(sc.sample_count)):
        return hit[1]  # type: ignore[no-any-return]
    if cached:
        computing = app.state.diagnosis_running.get(key)
        state = "one is being computed" if computing and not computing.done() else "none asked for"
        raise HTTPException(
            status_code=404,
            detail=f"no diagnosis of {spacecraft_id!r} yet ({state}); "
            "GET without cached=true computes one",
        )
    fut = _diagnosis_future(app, spacecraft_id, prior)
    try:
        return await asyncio.wrap_future(fut)
    except ValueError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
