"""``/v1/spacecraft``: register, list, show, set the orbit."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Annotated, Any

import sqlalchemy as sa
from fastapi import APIRouter, Depends, HTTPException
from fastapi.concurrency import run_in_threadpool

from orbitcal.errors import OrbitcalError
from service.auth import Principal, principal, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft, iso
from service.omm import normalise_omm
from service.schemas import ErrorPublic, OrbitIn, SpacecraftIn, SpacecraftPublic
from service.settings import Settings
from service.storage import Calibration, Spacecraft, find_window, read_tx, write_tx

if TYPE_CHECKING:  # orbitcal.orbit (sgp4) is imported when an orbit arrives, not at start-up
    from orbitcal.orbit import Orbit

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["spacecraft"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
    422: {"model": ErrorPublic},
}


def _check_orbit(tle: str | None, omm: dict[str, Any] | None) -> Orbit | None:
    """Parse and validate the orbit, as the CLI does; return it (None when neither is given).

    The OMM is first normalised (``service.omm.normalise_omm``: known keys, scalar and bounded
    values). The library's typed error (``OrbitProblemError``: malformed, unphysical or decayed
    elements) propagates to the one handler in ``service.handlers`` (422), with the body field
    named: ``"tle"``, or ``"omm.<KEY>"`` when the library named the element.
    """
    from orbitcal.orbit import Orbit

    if tle is None and omm is None:
        return None
    try:
        if tle is not None:
            return Orbit.from_tle(tle)
        assert omm is not None
        return Orbit.from_omm(normalise_omm(omm))
    except OrbitcalError as exc:
        _name_body_field(exc, "tle" if tle is not None else "omm")
        raise


def _name_body_field(exc: OrbitcalError, part: str) -> None:
    inner = getattr(exc, "field", None)
    # the body field, and inside it the element the library named: "omm.MEAN_MOTION"
    exc.field = part if inner is None or part == "tle" else f"{part}.{inner}"  # type: ignore[attr-defined]


def _check_epoch_near_data(conn: Any, sc: Any, orbit: Orbit, part: str, settings: Settings) -> None:
    """The CLI's guard (``orbitcal.orbit.check_epoch_near``, 14 days) against the data the next
    retraining of ``sc`` would read; nothing to compare with before the first sample."""
    from orbitcal.orbit import check_epoch_near

    window_s = float((sc.schedule or {}).get("window_s") or settings.window_s)
    window = find_window(
        conn, sc.pk, window_s=window_s, min_samples=settings.min_samples, now_utc_s=time.time()
    )
    if window.end_utc_s is None:
        return
    try:
        check_epoch_near(orbit, [window.start_utc_s, window.end_utc_s])
    except OrbitcalError as exc:
        message = str(exc).replace("--allow-stale-elements", "?allow_stale_elements=true")
        exc.args = (f"{message} (compared with the data the next retraining would read)",)
        _name_body_field(exc, part)
        raise


def _served(conn: Any, sc: Any) -> tuple[int, float | None] | None:
    cal = conn.execute(
        sa.select(Calibration.version, Calibration.holdout_rms_nt).where(
            Calibration.spacecraft_pk == sc.pk, Calibration.status == "in_service"
        )
    ).first()
    return None if cal is None else (int(cal[0]), cal[1])


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
    omm = None if body.omm is None else normalise_omm(body.omm)

    def create() -> SpacecraftPublic:
        with write_tx(engine) as conn:
            exists = conn.execute(sa.select(Spacecraft.pk).where(Spacecraft.id == body.id)).first()
            if exists is not None:
                raise HTTPException(status_code=409, detail=f"spacecraft {body.id!r} exists")
            conn.execute(
                sa.insert(Spacecraft).values(
                    id=body.id,
                    tle=body.tle,
                    omm=omm,
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
        return _public(sc, _served(conn, sc))


@router.put("/{spacecraft_id}/orbit", responses=_ERRORS)
async def set_orbit(
    spacecraft_id: str,
    body: OrbitIn,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("ingest")],
    allow_stale_elements: bool = False,
) -> SpacecraftPublic:
    """Replace the spacecraft's orbit (TLE or OMM); used by the next retraining.

    Refused (422) like the CLI refuses them: malformed or unphysical elements, and elements
    whose epoch lies more than 14 days from the data the next retraining would read (unless
    ``allow_stale_elements``). The answer gives the calibration in service.
    """
    orbit = await run_in_threadpool(_check_orbit, body.tle, body.omm)
    assert orbit is not None  # OrbitIn needs one of them
    omm = None if body.omm is None else normalise_omm(body.omm)

    def update() -> SpacecraftPublic:
        with write_tx(engine) as conn:
            sc = get_spacecraft(conn, spacecraft_id)
            if not allow_stale_elements:
                part = "tle" if body.tle is not None else "omm"
                _check_epoch_near_data(conn, sc, orbit, part, settings)
            conn.execute(
                sa.update(Spacecraft).where(Spacecraft.pk == sc.pk).values(tle=body.tle, omm=omm)
            )
            return _public(get_spacecraft(conn, spacecraft_id), _served(conn, sc))

    return await run_in_threadpool(update)
