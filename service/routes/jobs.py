"""``GET /v1/jobs/{job_id}``."""

from __future__ import annotations

from typing import Annotated

import sqlalchemy as sa
from fastapi import APIRouter, Depends, HTTPException

from service.auth import Principal, principal
from service.deps import EngineDep, iso, iso_or_none
from service.schemas import ErrorPublic, JobPublic
from service.storage import Job, Spacecraft, read_tx

__all__ = ["router"]

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])


@router.get(
    "/{job_id}",
    responses={
        401: {"model": ErrorPublic},
        403: {"model": ErrorPublic},
        404: {"model": ErrorPublic},
    },
)
def get_job(
    job_id: str, engine: EngineDep, who: Annotated[Principal, Depends(principal)]
) -> JobPublic:
    """A retraining job: ``queued | running | succeeded | failed``, its error or result."""
    with read_tx(engine) as conn:
        job = conn.execute(
            sa.select(Job, Spacecraft.id.label("spacecraft_id"))
            .join(Spacecraft, Spacecraft.pk == Job.spacecraft_pk)
            .where(Job.id == job_id)
        ).first()
    if job is None or not who.allows("read", job.spacecraft_id):
        # the same answer for "absent" and "not yours": job ids of others are not disclosed
        raise HTTPException(status_code=404, detail=f"unknown job {job_id!r}")
    sc = job.spacecraft_id
    return JobPublic(
        id=job.id,
        job_id=job.id,
        spacecraft=sc,
        kind=job.kind,
        trigger=job.trigger,
        status=job.status,
        error=job.error,
        params=job.params,
        result=job.result,
        created_at=iso(job.created_at),
        started_at=iso_or_none(job.started_at),
        finished_at=iso_or_none(job.finished_at),
    )
