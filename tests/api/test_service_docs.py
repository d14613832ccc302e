"""``/docs`` and ``/redoc`` work with no internet, and "Authorize" takes the ``X-API-Key``.

The browser tests (marked ``browser``) run headless Debian chromium with every host name but
127.0.0.1 resolving to nothing, record every request the pages make and take screenshots
(kept in ``$ORBITCAL_SCREENSHOT_DIR`` when set).
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
from cdp import Browser
from service_helpers import ADMIN_KEY, LiveServer, live_server, sqlite_settings

from service.routes.dashboard import DOCS_ASSETS

LIST_OP = "#operations-spacecraft-list_spacecraft_v1_spacecraft_get"


def keep_screenshot(path: Path) -> None:
    """Copy a screenshot to ``$ORBITCAL_SCREENSHOT_DIR`` (for a human to look at)."""
    target = os.environ.get("ORBITCAL_SCREENSHOT_DIR")
    if target:
        Path(target).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(target) / path.name)


# --- the OpenAPI document and the pages, without a browser -----------------------------------


def test_openapi_declares_the_api_key_scheme(server: LiveServer) -> None:
    with server.client(None) as c:
        spec = c.get("/openapi.json").json()
    scheme = spec["components"]["securitySchemes"]["X-API-Key"]
    assert scheme["type"] == "apiKey" and scheme["in"] == "header"
    assert scheme["name"] == "X-API-Key"
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            params = {p["name"].lower() for p in op.get("parameters", [])}
            assert "x-api-key" not in params, (method, path)  # the scheme, not a parameter
            if path in ("/healthz", "/dashboard"):
                assert "security" not in op, (method, path)
            else:
                assert op.get("security") == [{"X-API-Key": []}], (method, path)


def test_docs_pages_load_only_local_assets(server: LiveServer) -> None:
    with server.client(None) as c:
        for page, assets in (
            ("/docs", ["swagger-ui-bundle.js", "swagger-ui.css", "favicon.png"]),
            ("/redoc", ["redoc.standalone.js", "favicon.png"]),
        ):
            r = c.get(page)
            assert r.status_code == 200
            assert "default-src 'self'" in r.headers["content-security-policy"]
            urls = re.findall(r'(?:src|href)\s*=\s*["\']([^"\']+)', r.text)
            assert urls and all(u.startswith("/") for u in urls), (page, urls)
            assert "fonts.googleapis" not in r.text and "cdn." not in r.text
            for name in assets:
                assert f"/docs/assets/{name}" in urls, (page, name)
        for name, media_type in DOCS_ASSETS.items():
            r = c.get(f"/docs/assets/{name}")
            assert r.status_code == 200 and r.headers["content-type"] == media_type
            assert len(r.content) > 1000
        assert c.get("/docs/assets/..%2Fcore.py").status_code == 404
        assert c.get("/docs/assets/core.py").status_code == 404


# --- in chromium -----------------------------------------------------------------------------


def _execute_list(browser: Browser) -> str:
    """Press "Execute" on GET /v1/spacecraft; the HTTP status Swagger UI shows."""
    browser.evaluate(f"document.querySelector('{LIST_OP} .btn-clear')?.click()")
    browser.wait_for(f"!document.querySelector('{LIST_OP} .live-responses-table')")
    browser.evaluate(f"document.querySelector('{LIST_OP} .execute').click()")
    status: str = browser.wait_for(
        f"document.querySelector('{LIST_OP} .live-responses-table .response .response-col_status')"
        "?.textContent"
    )
    return status.strip()


@pytest.mark.browser
@pytest.mark.parametrize("auth", [True, False], ids=["auth-on", "auth-off"])
def test_swagger_ui_offline_with_authorize(tmp_path: Path, auth: bool) -> None:
    settings = sqlite_settings(tmp_path, auth=auth)
    with live_server(settings) as server, Browser() as browser:
        browser.navigate(server.url + "/docs")
        n_ops = browser.wait_for("document.querySelectorAll('.opblock').length")
        assert n_ops == len([op for ops in server.app.openapi()["paths"].values() for op in ops])
        assert browser.evaluate("!!document.querySelector('.auth-wrapper .authorize')")
        browser.evaluate(f"document.querySelector('{LIST_OP} .opblock-summary-control').click()")
        browser.wait_for(f"!!document.querySelector('{LIST_OP} .try-out__btn')")
        browser.evaluate(f"document.querySelector('{LIST_OP} .try-out__btn').click()")
        browser.wait_for(f"!!document.querySelector('{LIST_OP} .execute')")
        assert _execute_list(browser) == ("401" if auth else "200")
        # Authorize: the scheme's dialog takes the key; every call then carries it
        browser.evaluate("document.querySelector('.auth-wrapper .authorize').click()")
        browser.wait_for("!!document.querySelector('.modal-ux input')")
        assert "Name: X-API-Key\n\nIn: header" in browser.evaluate(
            "document.querySelector('.modal-ux').innerText"
        )
        browser.evaluate("document.querySelector('.modal-ux input').focus()")
        browser.type_text(ADMIN_KEY)
        browser.evaluate("document.querySelector('.modal-ux .auth-btn-wrapper .authorize').click()")
        browser.wait_for("document.querySelector('.modal-ux').innerText.includes('Logout')")
        browser.evaluate("document.querySelector('.modal-ux .btn-done').click()")
        assert _execute_list(browser) == "200"
        curl = browser.evaluate(f"document.querySelector('{LIST_OP} .curl-command').innerText")
        assert f"X-API-Key: {ADMIN_KEY}" in curl
        browser.evaluate("window.scrollTo(0, 0)")
        top = browser.screenshot(
            tmp_path / f"docs-swagger-top-{'auth' if auth else 'noauth'}.png", full_page=False
        )
        browser.evaluate(f"document.querySelector('{LIST_OP}').scrollIntoView()")
        shot = browser.screenshot(
            tmp_path / f"docs-swagger-{'auth' if auth else 'noauth'}.png", full_page=False
        )
        external = browser.external_requests(server.url)
        requested = list(browser.requested_urls)
        errors = list(browser.console_errors)
    keep_screenshot(shot)
    keep_screenshot(top)
    assert external == [], external
    assert f"{server.url}/docs/assets/swagger-ui-bundle.js" in requested
    assert f"{server.url}/v1/spacecraft" in requested
    assert errors == [], errors


@pytest.mark.browser
def test_redoc_offline(tmp_path: Path) -> None:
    with live_server(sqlite_settings(tmp_path)) as server, Browser() as browser:
        browser.navigate(server.url + "/redoc")
        n_ops = browser.wait_for(
            "document.querySelectorAll('[data-section-id^=\"operation/\"]').length"
        )
        assert n_ops == len([op for ops in server.app.openapi()["paths"].values() for op in ops])
        text = browser.evaluate("document.body.innerText")
        shot = browser.screenshot(tmp_path / "docs-redoc.png", full_page=False)
        external = browser.external_requests(server.url)
        blocked = list(browser.blocked_urls)
        requested = list(browser.requested_urls)
        failed = list(browser.error_responses)
    keep_screenshot(shot)
    assert "X-API-Key" in text and "List Spacecraft" in text
    assert external == [], external
    # ReDoc's sidebar asked for the Redocly logo from its CDN (refused by the CSP, logged by the
    # browser): the served bundle names a blank inline image instead, so nothing is asked for
    assert blocked == [], blocked
    assert not [u for u in requested if "redoc.ly" in u], requested
    assert failed == [], failed
