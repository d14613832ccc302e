"""``/v1/spacecraft``: register, list, show, set the orbit."""

from __future__ import annotations

import time
from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import APIRouter, Depends, HTTPException
from fastapi.concurrency import run_in_threadpool

from orbitcal.errors import OrbitcalError
from service.auth import Principal, principal, require_scope
from service.deps import EngineDep, get_spacecraft, iso
from service.schemas import ErrorPublic, OrbitIn, SpacecraftIn, SpacecraftPublic
from service.storage import Calibration, Spacecraft, read_tx, write_tx

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["spacecraft"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
    422: {"model": ErrorPublic},
}


def _check_orbit(tle: str | None, omm: dict[str, Any] | None) -> None:
    """Parse and validate the orbit; the library's typed error (``OrbitProblemError``: malformed,
    unphysical or decayed elements) propagates to the one handler in ``service.app`` (422), with
    the body field named when the library did not name one."""
    if tle is None and omm is None:
        return
    from orbitcal.orbit import Orbit

    try:
        if tle is not None:
            Orbit.from_tle(tle)
        else:
            assert omm is not None
            Orbit.from_omm(omm)
    except OrbitcalError as exc:
        part = "tle" if tle is not None else "omm"
        inner = getattr(exc, "field", None)
        # the body field, and inside it the element the library named: "omm.MEAN_MOTION"
        exc.field = part if inner is None or part == "tle" else f"{part}.{inner}"  # type: ignore[attr-defined]
        raise


def _public(sc: Any, cal: Any) -> SpacecraftPublic:
    return SpacecraftPublic(
        id=sc.id,
        attitude_frame=sc.attitude_frame,
        orbit="tle" if sc.tle else ("omm" if sc.omm else None),
        tle=sc.tle,
        schedule=sc.schedule,
        created_at=iso(sc.created_at),
        samples=int(sc.sample_count),
        calibration_version=None if cal is None else cal[0],
        holdout_rms_nt=None if cal is None else cal[1],
    )


@router.post("", status_code=201, responses={409: {"model": ErrorPublic}, **_ERRORS})
async def register_spacecraft(
    body: SpacecraftIn, engine: EngineDep, _who: Annotated[Principal, Depends(principal)]
) -> SpacecraftPublic:
    """Register a spacecraft (``admin`` or ``ingest:<id>`` / ``ingest:*`` scope)."""
    if not _who.allows("ingest", body.id):
        raise HTTPException(status_code=403, detail=f"this key lacks the scope ingest:{body.id}")
    await run_in_threadpool(_check_orbit, body.tle, body.omm)

    def create() -> SpacecraftPublic:
        with write_tx(engine) as conn:
            exists = conn.execute(sa.select(Spacecraft.pk).where(Spacecraft.id == body.id)).first()
            if exists is not None:
                raise HTTPException(status_code=409, detail=f"spacecraft {body.id!r} exists")
            conn.execute(
                sa.insert(Spacecraft).values(
                    id=body.id,
                    tle=body.tle,
                    omm=body.omm,
                    attitude_frame=body.attitude_frame,
                    schedule=None
                    if body.schedule is None
                    else body.schedule.model_dump(exclude_none=True),
                    created_at=time.time(),
                    sample_count=0,
                    samples_at_last_job=0,
                )
            )
            sc = get_spacecraft(conn, body.id)
            return _public(sc, None)

    return await run_in_threadpool(create)


@router.get("", responses=_ERRORS)
def list_spacecraft(
    engine: EngineDep, who: Annotated[Principal, Depends(principal)]
) -> list[SpacecraftPublic]:
    """Every spacecraft the key may read, with its calibration in service."""
    with read_tx(engine) as conn:
        rows = conn.execute(
            sa.select(
                Spacecraft,
                Calibration.version.label("cal_version"),
                Calibration.holdout_rms_nt.label("cal_rms"),
            )
            .outerjoin(
                Calibration,
                sa.and_(
                    Calibration.spacecraft_pk == Spacecraft.pk, Calibration.status == "in_service"
                ),
            )
            .order_by(Spacecraft.id)
        ).all()
    return [
        _public(r, None if r.cal_version is None else (r.cal_version, r.cal_rms))
        for r in rows
        if who.allows("read", r.id)
    ]


@router.get("/{spacecraft_id}", responses=_ERRORS)
def show_spacecraft(
    spacecraft_id: str, engine: EngineDep, _who: Annotated[Principal, require_scope("read")]
) -> SpacecraftPublic:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        cal = conn.execute(
            sa.select(Calibration.version, Calibration.holdout_rms_nt).where(
                Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
            )
        ).first()
    return _public(sc, None if cal is None else tuple(cal))


@router.put("/{spacecraft_id}/orbit", responses=_ERRORS)
async def set_orbit(
    spacecraft_id: str,
    body: OrbitIn,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("ingest")],
) -> SpacecraftPublic:
    """Replace the spacecraft's orbit (TLE or OMM); used by the next retraining."""
    await run_in_threadpool(_check_orbit, body.tle, body.omm)

    def update() -> SpacecraftPublic:
        with write_tx(engine) as conn:
            sc = get_spacecraft(conn, spacecraft_id)
            conn.execute(
                sa.update(Spacecraft)
                .where(Spacecraft.pk == sc.pk)
                .values(tle=body.tle, omm=body.omm)
            )
            return _public(get_spacecraft(conn, spacecraft_id), None)

    return await run_in_threadpool(update)
