"""The operator's pages: ``/dashboard`` and the API documentation (``/docs``, ``/redoc``).

Every asset these pages load is served by the service itself, so they work with no internet:
Swagger UI and ReDoc come from the package data of ``fastapi-offline`` (pinned in pyproject.toml),
the dashboard draws its plots as SVG in its own script.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from typing import Annotated, Any

import sqlalchemy as sa
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from service.auth import Principal, require_scope
from service.deps import EngineDep, get_spacecraft, iso, iso_or_none
from service.numeric import ASCII_INTEGER
from service.schemas import ErrorPublic
from service.state import service_state
from service.storage import IngestLog, Job, read_tx

__all__ = ["CSP", "DOCS_ASSETS", "router"]

router = APIRouter(tags=["dashboard"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorPublic},
    403: {"model": ErrorPublic},
    404: {"model": ErrorPublic},
}
_DAY_US = 86_400_000_000
#: An HTML page on success; errors (401, 404, 429, ...) stay JSON (ErrorPublic). A route with
#: ``response_class=HTMLResponse`` would document those errors as text/html too.
_HTML: dict[int | str, dict[str, Any]] = {
    200: {"description": "an HTML page", "content": {"text/html": {"schema": {"type": "string"}}}}
}

#: Files of ``fastapi_offline/static`` the documentation pages load, with their media types.
DOCS_ASSETS = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
    "redoc.standalone.js": "text/javascript; charset=utf-8",
    "favicon.png": "image/png",
}
_ASSETS_PATH = "/docs/assets"
#: These pages load nothing from another host: the browser refuses it (ReDoc's sidebar shows a
#: Redocly logo from a CDN, which is thus never fetched; the page is complete without it).
CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self' blob:; "
    "worker-src 'self' blob:; frame-ancestors 'self'; base-uri 'self'; form-action 'self'"
)
_PAGE_HEADERS = {"Content-Security-Policy": CSP, "Cache-Control": "no-store"}


@router.get("/", include_in_schema=False)
def root() -> RedirectResponse:
    return RedirectResponse("/dashboard")


@router.get("/dashboard", responses=_HTML)
def dashboard() -> HTMLResponse:
    """The operator's page: spacecraft, calibration in service, plots, diagnosis, quarantine.

    The key is typed into the page and kept in the browser (``localStorage``), or given as
    ``/dashboard#key=<API key>``: a URL fragment never reaches the server or its logs.
    """
    page = resources.files("service").joinpath("static/dashboard.html").read_text("utf-8")
    return HTMLResponse(page, headers=_PAGE_HEADERS)


#: ReDoc's sidebar shows the Redocly logo from a CDN (``<img src="https://cdn.redoc.ly/…">``):
#: the served bundle names a blank inline image instead, so the page asks no other host for
#: anything (the CSP below would refuse it, but the browser would still try and log it).
REDOC_LOGO_URL = "https://cdn.redoc.ly/redoc/logo-mini.svg"
_BLANK_SVG = "data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg' width='1' height='1'/%3E"


@cache
def _asset(name: str) -> bytes:
    data = resources.files("fastapi_offline").joinpath("static", name).read_bytes()
    if name == "redoc.standalone.js":
        data = data.replace(REDOC_LOGO_URL.encode(), _BLANK_SVG.encode())
    return data


@router.get(_ASSETS_PATH + "/{name}", include_in_schema=False)
def docs_asset(name: str) -> Response:
    """Swagger UI / ReDoc file from the installed package (no CDN)."""
    if name not in DOCS_ASSETS:
        raise HTTPException(status_code=404, detail=f"no documentation asset {name!r}")
    return Response(
        _asset(name),
        media_type=DOCS_ASSETS[name],
        headers={"Cache-Control": "public, max-age=86400"},
    )


@router.get("/favicon.ico", include_in_schema=False)
def favicon() -> Response:
    """The icon browsers ask for on every page (the dashboard links it too): no 404 in the logs."""
    return docs_asset("favicon.png")


def _prefix(request: Request) -> str:
    return str(request.scope.get("root_path", "")).rstrip("/")


@router.get("/docs", include_in_schema=False)
def swagger_ui(request: Request) -> HTMLResponse:
    """Swagger UI on ``/openapi.json``; "Authorize" takes the ``X-API-Key``."""
    base = _prefix(request)
    page = get_swagger_ui_html(
        openapi_url=base + str(request.app.openapi_url),
        title=f"{request.app.title} API",
        swagger_js_url=f"{base}{_ASSETS_PATH}/swagger-ui-bundle.js",
        swagger_css_url=f"{base}{_ASSETS_PATH}/swagger-ui.css",
        swagger_favicon_url=f"{base}{_ASSETS_PATH}/favicon.png",
        swagger_ui_parameters={
            # no badge fetched from the public validator; the key survives a reload
            "validatorUrl": None,
            "persistAuthorization": True,
        },
    )
    page.headers.update(_PAGE_HEADERS)
    return page


@router.get("/redoc", include_in_schema=False)
def redoc(request: Request) -> HTMLResponse:
    """ReDoc on ``/openapi.json`` (system fonts: no font service)."""
    base = _prefix(request)
    page = get_redoc_html(
        openapi_url=base + str(request.app.openapi_url),
        title=f"{request.app.title} API",
        redoc_js_url=f"{base}{_ASSETS_PATH}/redoc.standalone.js",
        redoc_favicon_url=f"{base}{_ASSETS_PATH}/favicon.png",
        with_google_fonts=False,
    )
    page.headers.update(_PAGE_HEADERS)
    return page


# --- what the dashboard reads besides the calibration routes ---------------------------------


def _activity(engine: Any, spacecraft_id: str, max_jobs: int) -> dict[str, Any]:
    with read_tx(engine) as conn:
        sc = get_spacecraft(conn, spacecraft_id)
        per_day = conn.execute(
            sa.text(
                "SELECT t_utc_us / :day AS d, COUNT(*) FROM samples "
                "WHERE spacecraft_pk = :pk GROUP BY d ORDER BY d"
            ),
            {"day": _DAY_US, "pk": sc.pk},
        ).all()
        uploads = conn.execute(
            sa.select(IngestLog)
            .where(IngestLog.spacecraft_pk == sc.pk)
            .order_by(IngestLog.received_at.desc())
        ).all()
        jobs = conn.execute(
            sa.select(Job)
            .where(Job.spacecraft_pk == sc.pk)
            .order_by(Job.created_at.desc())
            .limit(max_jobs)
        ).all()
    arrivals: dict[int, dict[str, Any]] = {}
    for u in uploads:
        d = int(u.received_at // 86400)
        entry = arrivals.setdefault(
            d, {"day": iso(d * 86400.0)[:10], "uploads": 0, "accepted": 0, "rejected": 0}
        )
        entry["uploads"] += 1
        entry["accepted"] += int(u.accepted)
        entry["rejected"] += int(u.rejected)
    retrainings = []
    for j in jobs:
        result = j.result or {}
        retrainings.append(
            {
                "job_id": j.id,
                "trigger": j.trigger,
                "status": j.status,
                "created_at": iso(j.created_at),
                "finished_at": iso_or_none(j.finished_at),
                "method": (j.params or {}).get("method") or result.get("method"),
                "version": result.get("version"),
                "promoted": result.get("promoted"),
                "excluded": result.get("excluded", {}),
                "excluded_total": result.get("excluded_total", 0),
                "error": j.error,
            }
        )
    return {
        "spacecraft": sc.id,
        "samples_per_day": [
            {"day": iso(int(d) * 86400.0)[:10], "samples": int(n)} for d, n in per_day
        ],
        "uploads_per_day": [arrivals[d] for d in sorted(arrivals)],
        "samples": int(sc.sample_count),
        "ingest": {
            "uploads": len(uploads),
            "accepted": sum(int(u.accepted) for u in uploads),
            "duplicates": sum(int(u.duplicates) for u in uploads),
            "rejected": sum(int(u.rejected) for u in uploads),
            "recent_rejections": [
                {
                    "received_at": iso(u.received_at),
                    "format": u.fmt,
                    "rejected": int(u.rejected),
                    "examples": u.examples or [],
                }
                for u in uploads
                if u.rejected
            ][:20],
        },
        "retrainings": retrainings,
    }


@router.get("/v1/spacecraft/{spacecraft_id}/activity", responses=_ERRORS)
async def activity(
    spacecraft_id: str,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    max_jobs: Annotated[int, Query(ge=1, le=1000), ASCII_INTEGER] = 50,
) -> dict[str, Any]:
    """What happened to a spacecraft's data, for the dashboard's plots.

    ``samples_per_day``: samples stored per UTC day of their sample time; ``uploads_per_day``: per
    UTC day of arrival, the uploads and the rows they had accepted and rejected; ``ingest``:
    totals and the latest uploads that had rejected rows, with examples of the reasons;
    ``retrainings``: the latest jobs (newest first) with the rows each left out and why.
    """
    return await run_in_threadpool(_activity, engine, spacecraft_id, max_jobs)


@router.get("/v1/spacecraft/{spacecraft_id}/diagnosis/latest", responses=_ERRORS)
def latest_diagnosis(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    prior: bool = False,
) -> dict[str, Any]:
    """The latest diagnosis report computed so far, or none yet (200 either way: "nothing yet"
    is the dashboard's normal empty state, not an error; 404 only for an unknown spacecraft).

    ``state`` is ``ready`` (``report`` holds it), ``computing`` (one is being computed) or
    ``none`` (none asked for: ``GET .../diagnosis`` computes one).
    """
    with read_tx(engine) as conn:
        get_spacecraft(conn, spacecraft_id)
    key = (spacecraft_id, prior)
    diagnoses = service_state(request).diagnoses
    hit = diagnoses.latest(key)
    if hit is not None:
        return {"state": "ready", "report": hit[1].to_json()}
    return {"state": "computing" if diagnoses.computing(key) else "none", "report": None}


@router.get("/v1/spacecraft/{spacecraft_id}/diagnosis/report.html", responses={**_ERRORS, **_HTML})
def diagnosis_report_html(
    spacecraft_id: str,
    request: Request,
    engine: EngineDep,
    _who: Annotated[Principal, require_scope("read")],
    prior: bool = False,
) -> HTMLResponse:
    """The latest diagnosis report computed so far as an HTML page (404 if none yet)."""
    from orbitcal.diagnose.html_report import report_html

    with read_tx(engine) as conn:
        get_spacecraft(conn, spacecraft_id)
    hit = service_state(request).diagnoses.latest((spacecraft_id, prior))
    if hit is None:
        raise HTTPException(
            status_code=404,
            detail=f"no diagnosis of {spacecraft_id!r} yet; GET .../diagnosis computes one",
        )
    page = report_html(hit[1].to_json(), title=f"orbitcal diagnosis of {spacecraft_id}")
    return HTMLResponse(page, headers={"Cache-Control": "no-store"})
