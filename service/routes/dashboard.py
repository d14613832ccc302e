"""``GET /dashboard``: a static page that reads the API with the key given in the URL fragment."""

from __future__ import annotations

from importlib import resources

from fastapi import APIRouter
from fastapi.responses import HTMLResponse, RedirectResponse

__all__ = ["router"]

router = APIRouter(tags=["dashboard"])


@router.get("/", include_in_schema=False)
def root() -> RedirectResponse:
    return RedirectResponse("/dashboard")


@router.get("/dashboard", response_class=HTMLResponse)
def dashboard() -> HTMLResponse:
    """Spacecraft list, calibration in service and history, residual-vs-time plot, diagnosis.

    Open ``/dashboard#key=<API key>``: the fragment never reaches the server or its logs.
    """
    page = resources.files("service").joinpath("static/dashboard.html").read_text("utf-8")
    return HTMLResponse(page, headers={"Cache-Control": "no-store"})
