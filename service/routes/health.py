"""Calibration health (issue 47): the calibration in service against the newest data.

``GET /v1/spacecraft/{id}/health`` is CONTRACT section 3, word for word; ``…/health/series`` is
the series behind it (one point per scored batch), for the dashboard and for plotting.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request

from service.auth import Principal, require_scope
from service.deps import EngineDep, SettingsDep, get_spacecraft, iso_or_none
from service.health import health_answer, series
from service.schemas import ErrorPublic, HealthPointPublic, HealthPublic
from service.storage import read_tx

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["health"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
}


@router.get("/{spacecraft_id}/health", responses=_ERRORS)
def health(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    settings: SettingsDep,
    _who: Annotated[Principal, require_scope("read")],
) -> HealthPublic:
    """The calibration in service against the newest data: its RMS on the newest scored batch
    (CONTRACT "Definitions"), that batch's noise floor, whether the change rule found it stale
    (docs/design.md, "Calibration health"), when the change began and when the next retraining
    is due. 404 before the first calibration. Uploads answered before this request are
    scored first."""
    with read_tx(engine) as conn:
        pk = get_spacecraft(conn, spacecraft_id).pk
    request.app.state.health.wait(pk)
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        answer = health_answer(conn, settings, sc)
    if answer is None:
        raise HTTPException(status_code=404, detail=f"{spacecraft_id!r} has no calibration yet")
    for key in ("in_service_since", "change_at", "next_retraining"):
        answer[key] = iso_or_none(answer[key])
    return HealthPublic(**answer)


@router.get("/{spacecraft_id}/health/series", responses=_ERRORS)
def health_series(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    limit: Annotated[int, Query(ge=1, le=100_000)] = 2000,
) -> list[HealthPointPublic]:
    """The health series, oldest first: per scored batch the version scored, its kind (``new``
    samples of an upload, or ``holdout``: the version's own held-out block when it went into
    service), span, samples, RMS, noise floor, the held-out RMS it is compared with, the CUSUM,
    stale, and on the alarm's point when the change began."""
    with read_tx(engine) as conn:
        pk = get_spacecraft(conn, spacecraft_id).pk
    request.app.state.health.wait(pk)
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        points = series(conn, sc.pk, limit=limit)
    for p in points:
        for key in ("start", "end", "change_at", "scored_at"):
            p[key] = iso_or_none(p[key])
    return [HealthPointPublic(**p) for p in points]
