"""``/v1/keys``: API key administration (``admin`` scope)."""

from __future__ import annotations

from typing import Annotated

import sqlalchemy as sa
from fastapi import APIRouter, Depends, HTTPException, Request, Response

from service.auth import Principal, create_key, require_admin
from service.deps import EngineDep, iso
from service.schemas import ApiKeyCreated, ApiKeyIn, ApiKeyPublic, ErrorPublic
from service.storage import ApiKey, read_tx, write_tx

__all__ = ["router"]

router = APIRouter(
    prefix="/v1/keys",
    tags=["keys"],
    responses={401: {"model": ErrorPublic}, 403: {"model": ErrorPublic}},
)
AdminDep = Annotated[Principal, Depends(require_admin)]


@router.post("", status_code=201)
def create_api_key(
    body: ApiKeyIn, request: Request, response: Response, _admin: AdminDep
) -> ApiKeyCreated:
    """Create a key with scopes; the key is in this answer only (stored as sha256), which no
    cache may keep (``Cache-Control: no-store``)."""
    response.headers["Cache-Control"] = "no-store"
    key, prefix = create_key(request, body.name, body.scopes)
    return ApiKeyCreated(key=key, prefix=prefix, name=body.name, scopes=sorted(set(body.scopes)))


@router.get("")
def list_api_keys(engine: EngineDep, _admin: AdminDep) -> list[ApiKeyPublic]:
    with read_tx(engine) as conn:
        keys = conn.execute(sa.select(ApiKey).order_by(ApiKey.pk)).all()
    return [
        ApiKeyPublic(
            prefix=k.prefix,
            name=k.name,
            scopes=k.scopes,
            created_at=iso(k.created_at),
            revoked=k.revoked,
        )
        for k in keys
    ]


@router.delete("/{prefix}", status_code=204, responses={404: {"model": ErrorPublic}})
def revoke_api_key(prefix: str, request: Request, engine: EngineDep, _admin: AdminDep) -> None:
    with write_tx(engine) as conn:
        done = conn.execute(
            sa.update(ApiKey).where(ApiKey.prefix == prefix).values(revoked=True)
        ).rowcount
    if not done:
        raise HTTPException(status_code=404, detail=f"no key with prefix {prefix!r}")
    request.app.state.key_cache.clear()  # this process forgets the key at once
