"""``/healthz`` and ``/metrics``."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST

from service.auth import Principal, principal
from service.state import service_state

__all__ = ["router"]

router = APIRouter(tags=["operations"])


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """Liveness (no authentication)."""
    return {"status": "ok"}


@router.get("/metrics", response_class=Response)
def metrics(request: Request, who: Annotated[Principal, Depends(principal)]) -> Response:
    """Prometheus text exposition (needs a valid key, like every route but ``/healthz``).

    Scoped like every other answer: series of the spacecraft the key may read, and the
    fleet-wide series only for a key that may read every spacecraft (``read:*``, ``admin``).
    """
    text = service_state(request).metrics.exposition(
        may_read=lambda sc: who.allows("read", sc), fleet=who.reads_everything()
    )
    return Response(text, media_type=CONTENT_TYPE_LATEST)
