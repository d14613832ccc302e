"""Operators' hold on stored samples: quarantine (reversible), release, delete, and the audit log.

A quarantined time range stays stored but is left out of retraining, the residual view and the
diagnosis until it is released; a deletion removes the samples for good. Both need the
spacecraft's write scope (``ingest:<id>``, ``ingest:*`` or ``admin``), are recorded in the audit
log (who, when, range, count) and bump the spacecraft's ``data_revision`` so that answers cached
on the samples (the diagnosis) are recomputed.
"""

from __future__ import annotations

import time
from typing import Annotated, Any, Literal

import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Path, Query
from pydantic import BaseModel, ConfigDict, Field

from orbitcal.errors import BadInputError
from orbitcal.timescales import parse_instant_utc_s
from service.auth import Principal, require_scope
from service.deps import MAX_ROW_ID, EngineDep, get_spacecraft, iso, iso_or_none
from service.numeric import ASCII_INTEGER
from service.schemas import ErrorPublic
from service.storage import (
    DataAudit,
    Quarantine,
    bump_data_revision,
    count_samples,
    delete_samples,
    read_tx,
    write_tx,
)

__all__ = ["router"]

router = APIRouter(prefix="/v1/spacecraft", tags=["quarantine"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
    409: {"model": ErrorPublic},
    422: {"model": ErrorPublic},
}

TimeIn = Annotated[
    float | str,
    Field(description="ISO-8601 with a UTC offset (e.g. `2022-08-01T00:00:00Z`) or Unix seconds"),
]


class QuarantineIn(BaseModel):
    """A time range to quarantine (both ends inclusive)."""

    model_config = ConfigDict(extra="forbid")

    start: TimeIn
    end: TimeIn
    reason: str = Field(default="", max_length=1000)


class QuarantinePublic(BaseModel):
    id: int
    start: str
    end: str
    reason: str
    #: Samples in the range when it was quarantined.
    n_samples: int
    created_by: str
    created_at: str
    active: bool
    released_at: str | None = None
    released_by: str | None = None
    #: Samples the release returned to use (on the release answer only).
    n_released: int | None = None


class DeletedPublic(BaseModel):
    start: str
    end: str
    deleted: int


class AuditPublic(BaseModel):
    action: Literal["quarantine", "release", "delete"]
    start: str
    end: str
    n_samples: int
    who: str
    at: str
    quarantine_id: int | None = None
    reason: str | None = None


def _range(start: float | str, end: float | str, *, numeric_text: bool = False) -> tuple[int, int]:
    """The range's ends in UTC µs; the library's BadInputError (422) names a bad end."""
    start_us, end_us = (
        round(parse_instant_utc_s(value, field=name, numeric_text=numeric_text) * 1e6)
        for value, name in ((start, "start"), (end, "end"))
    )
    if end_us < start_us:
        raise BadInputError("end: the range ends before it starts", field="end")
    return start_us, end_us


def _public(q: Any, n_released: int | None = None) -> QuarantinePublic:
    return QuarantinePublic(
        id=q.pk,
        start=iso(q.start_us / 1e6),
        end=iso(q.end_us / 1e6),
        reason=q.reason,
        n_samples=int(q.n_samples),
        created_by=q.created_by,
        created_at=iso(q.created_at),
        active=q.released_at is None,
        released_at=iso_or_none(q.released_at),
        released_by=q.released_by,
        n_released=n_released,
    )


def _audit(
    conn: Any, sc_pk: int, action: str, start_us: int, end_us: int, n: int, **kw: Any
) -> None:
    conn.execute(
        sa.insert(DataAudit).values(
            spacecraft_pk=sc_pk,
            action=action,
            start_us=start_us,
            end_us=end_us,
            n_samples=n,
            at=time.time(),
            **kw,
        )
    )


@router.post("/{spacecraft_id}/quarantines", status_code=201, responses=_ERRORS)
def quarantine(
    spacecraft_id: str,
    body: QuarantineIn,
    engine: EngineDep,
    who: Annotated[Principal, require_scope("ingest")],
) -> QuarantinePublic:
    """Keep the samples in ``[start, end]`` out of retraining and diagnosis (reversible).

    Samples ingested later into the range are held too, until the quarantine is released.
    """
    start_us, end_us = _range(body.start, body.end)
    with write_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        n = count_samples(conn, sc.pk, start_utc_s=start_us / 1e6, end_utc_s=end_us / 1e6)
        pk = conn.execute(
            sa.insert(Quarantine)
            .values(
                spacecraft_pk=sc.pk,
                start_us=start_us,
                end_us=end_us,
                reason=body.reason,
                created_by=who.name,
                created_at=time.time(),
                n_samples=n,
            )
            .returning(Quarantine.pk)
        ).scalar_one()
        _audit(conn, sc.pk, "quarantine", start_us, end_us, n, who=who.name, quarantine_pk=pk,
               reason=body.reason)  # fmt: skip
        bump_data_revision(conn, sc.pk)
        row = conn.execute(sa.select(Quarantine).where(Quarantine.pk == pk)).one()
    return _public(row)


@router.get("/{spacecraft_id}/quarantines", responses=_ERRORS)
def list_quarantines(
    spacecraft_id: str,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    active: Annotated[
        bool | None, Query(description="only active (true) or only released (false) ones")
    ] = None,
) -> list[QuarantinePublic]:
    """Every quarantine of the spacecraft, newest first (``active`` ones hold their samples)."""
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        query = sa.select(Quarantine).where(Quarantine.spacecraft_pk == sc.pk)
        if active is not None:
            query = query.where(
                Quarantine.released_at.is_(None) if active else Quarantine.released_at.is_not(None)
            )
        rows = conn.execute(query.order_by(Quarantine.pk.desc())).all()
    return [_public(q) for q in rows]


@router.delete("/{spacecraft_id}/quarantines/{quarantine_id}", responses=_ERRORS)
def release(
    spacecraft_id: str,
    quarantine_id: Annotated[
        int, Path(ge=1, le=MAX_ROW_ID, description="the quarantine's id"), ASCII_INTEGER
    ],
    engine: EngineDep,
    who: Annotated[Principal, require_scope("ingest")],
) -> QuarantinePublic:
    """Release a quarantine: its samples count again (``n_released`` of them, other active
    quarantines overlapping the range keep theirs). 409 when it was already released."""
    with write_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        q = conn.execute(
            sa.select(Quarantine).where(
                Quarantine.pk == quarantine_id, Quarantine.spacecraft_pk == sc.pk
            )
        ).first()
        if q is None:
            raise HTTPException(
                status_code=404,
                detail=f"spacecraft {spacecraft_id!r} has no quarantine {quarantine_id}",
            )
        if q.released_at is not None:
            raise HTTPException(
                status_code=409,
                detail=f"quarantine {quarantine_id} was already released by {q.released_by} "
                f"at {iso(q.released_at)}",
            )
        lo, hi = q.start_us / 1e6, q.end_us / 1e6
        held_before = count_samples(conn, sc.pk, start_utc_s=lo, end_utc_s=hi) - count_samples(
            conn, sc.pk, start_utc_s=lo, end_utc_s=hi, include_quarantined=False
        )
        conn.execute(
            sa.update(Quarantine)
            .where(Quarantine.pk == q.pk)
            .values(released_at=time.time(), released_by=who.name)
        )
        held_after = count_samples(conn, sc.pk, start_utc_s=lo, end_utc_s=hi) - count_samples(
            conn, sc.pk, start_utc_s=lo, end_utc_s=hi, include_quarantined=False
        )
        n = held_before - held_after
        _audit(conn, sc.pk, "release", q.start_us, q.end_us, n, who=who.name, quarantine_pk=q.pk)
        bump_data_revision(conn, sc.pk)
        row = conn.execute(sa.select(Quarantine).where(Quarantine.pk == q.pk)).one()
    return _public(row, n_released=n)


@router.delete("/{spacecraft_id}/telemetry", responses=_ERRORS)
def delete_range(
    spacecraft_id: str,
    engine: EngineDep,
    who: Annotated[Principal, require_scope("ingest")],
    start: Annotated[str, Query(description="ISO-8601 with offset, or Unix seconds")],
    end: Annotated[str, Query(description="ISO-8601 with offset, or Unix seconds")],
) -> DeletedPublic:
    """Delete the stored samples in ``[start, end]`` for good (quarantined or not)."""
    start_us, end_us = _range(start, end, numeric_text=True)
    with write_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        n = delete_samples(conn, sc.pk, start_us, end_us)
        _audit(conn, sc.pk, "delete", start_us, end_us, n, who=who.name)
    return DeletedPublic(start=iso(start_us / 1e6), end=iso(end_us / 1e6), deleted=n)


@router.get("/{spacecraft_id}/data-audit", responses=_ERRORS)
def data_audit(
    spacecraft_id: str,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    limit: Annotated[int, Query(ge=1, le=10000), ASCII_INTEGER] = 1000,
) -> list[AuditPublic]:
    """Who quarantined, released or deleted which samples, newest first."""
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        rows = conn.execute(
            sa.select(DataAudit)
            .where(DataAudit.spacecraft_pk == sc.pk)
            .order_by(DataAudit.pk.desc())
            .limit(limit)
        ).all()
    return [
        AuditPublic(
            action=a.action,
            start=iso(a.start_us / 1e6),
            end=iso(a.end_us / 1e6),
            n_samples=int(a.n_samples),
            who=a.who,
            at=iso(a.at),
            quarantine_id=a.quarantine_pk,
            reason=a.reason,
        )
        for a in rows
    ]
