"""Headless Debian chromium driven over the DevTools protocol on a pipe.

No browser-automation package is needed: with ``--remote-debugging-pipe`` Chromium reads
NUL-terminated JSON commands on file descriptor 3 and writes answers and events on 4.
:class:`Browser` opens one page, records the URL of every request the page makes (to prove that
nothing leaves the machine), evaluates scripts, types text and takes screenshots. Host names other
than 127.0.0.1 resolve to nothing (``--host-resolver-rules``), so a page that needed a CDN would
visibly fail.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}


def chromium_path() -> str:
    """Debian chromium, or skip (fail in CI, where .ci/run installs it)."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        if IN_CI:
            pytest.fail("Debian chromium is not installed (.ci/run installs it)")
        pytest.skip("chromium is not installed")
    return path


#: CDP errors of a page that is navigating: no context to evaluate in yet, not a failure.
NAVIGATING = (
    "Inspected target navigated or closed",
    "Cannot find context with specified id",
    "Execution context was destroyed",
)


class CdpError(RuntimeError):
    """A DevTools command answered an error, or the browser went away."""


class Browser:
    """One headless chromium with one page, spoken to over the DevTools pipe."""

    def __init__(self, *, width: int = 1280, height: int = 1000, timeout_s: float = 60.0) -> None:
        self.timeout_s = timeout_s
        self.profile = tempfile.mkdtemp(prefix="orbitcal-chromium-")
        # chromium's stderr (a pipe could fill and block it); closed in close()
        self._log = tempfile.TemporaryFile()  # noqa: SIM115
        to_browser_r, self._to_browser_w = os.pipe()
        self._from_browser_r, from_browser_w = os.pipe()
        args = [
            chromium_path(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--hide-scrollbars",
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
            f"--window-size={width},{height}",
            f"--user-data-dir={self.profile}",
            "--remote-debugging-pipe",
            "about:blank",
        ]
        # fds 3 and 4 of the browser are our pipe ends (bash moves them there: dash refuses fds > 9)
        shell = f'exec "$@" 3<&{to_browser_r} 4>&{from_browser_w}'
        self.proc = subprocess.Popen(
            ["/bin/bash", "-c", shell, "bash", *args],
            pass_fds=(to_browser_r, from_browser_w),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=self._log,
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict[str, Any]] = []
        self.requested_urls: list[str] = []
        self.blocked_urls: list[str] = []  # refused by the browser itself (e.g. the page's CSP)
        self._request_urls: dict[str, str] = {}
        self.console_errors: list[str] = []
        #: "STATUS URL" of every answer >= 400 (a 404 for a favicon is logged by the browser
        #: as a console error outside the page's scripts, so console_errors would miss it)
        self.error_responses: list[str] = []
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)[
            "sessionId"
        ]
        for domain in ("Page", "Network", "Runtime"):
            self.page(f"{domain}.enable")

    # --- protocol -------------------------------------------------------------------------------

    def _send(self, message: dict[str, Any]) -> None:
        os.write(self._to_browser_w, json.dumps(message).encode() + b"\0")

    def _receive(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            if time.monotonic() > deadline:
                raise CdpError("no answer from chromium in time")
            chunk = os.read(self._from_browser_r, 1 << 20)
            if not chunk:
                raise CdpError("chromium closed the pipe: " + self._stderr())
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        message: dict[str, Any] = json.loads(raw)
        return message

    def _stderr(self) -> str:
        self._log.seek(0)
        return self._log.read().decode(errors="replace")[-2000:]

    def _record(self, event: dict[str, Any]) -> None:
        self.events.append(event)
        method, params = event.get("method"), event.get("params", {})
        if method == "Network.requestWillBeSent":
            self.requested_urls.append(params["request"]["url"])
            self._request_urls[params["requestId"]] = params["request"]["url"]
        elif method == "Network.responseReceived" and params["response"]["status"] >= 400:
            self.error_responses.append(
                f"{params['response']['status']} {params['response']['url']}"
            )
        elif method == "Network.loadingFailed" and params.get("blockedReason"):
            self.blocked_urls.append(self._request_urls.get(params["requestId"], "?"))
        elif method == "Runtime.exceptionThrown":
            self.console_errors.append(json.dumps(params["exceptionDetails"])[:500])
        elif method == "Runtime.consoleAPICalled" and params.get("type") == "error":
            self.console_errors.append(json.dumps(params.get("args"))[:500])

    def call(self, method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        """Send one command and wait for its answer (events met meanwhile are recorded)."""
        self._next_id += 1
        ident = self._next_id
        message: dict[str, Any] = {"id": ident, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self._send(message)
        deadline = time.monotonic() + self.timeout_s
        while True:
            answer = self._receive(deadline)
            if answer.get("id") == ident:
                if "error" in answer:
                    raise CdpError(f"{method}: {answer['error']}")
                result: dict[str, Any] = answer.get("result", {})
                return result
            self._record(answer)

    def page(self, method: str, **params: Any) -> dict[str, Any]:
        """A command to the page's session."""
        return self.call(method, session=self.session, **params)

    # --- conveniences ---------------------------------------------------------------------------

    def navigate(self, url: str) -> None:
        self.page("Page.navigate", url=url)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression (promises awaited)."""
        answer = self.page(
            "Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True
        )
        if "exceptionDetails" in answer:
            raise CdpError(f"{expression[:80]}: {answer['exceptionDetails']}")
        return answer["result"].get("value")

    def wait_for(self, expression: str, timeout_s: float = 30.0) -> Any:
        """Poll until ``expression`` is truthy; return its value."""
        deadline = time.monotonic() + timeout_s
        guarded = f"(() => {{ try {{ return ({expression}); }} catch (e) {{ return null; }} }})()"
        while True:
            try:
                value = self.evaluate(guarded)  # null while the page is still loading
            except CdpError as exc:
                # Asked between a reload's unloading and the new document's context (CI at
                # 1544911: "Inspected target navigated or closed" right after location.reload()).
                if not any(m in str(exc) for m in NAVIGATING):
                    raise
                value = None
            if value:
                return value
            if time.monotonic() > deadline:
                raise CdpError(f"timed out waiting for {expression!r}")
            time.sleep(0.1)

    def type_text(self, text: str) -> None:
        """Type into the focused element (as a keyboard would: frameworks see input events)."""
        self.page("Input.insertText", text=text)

    def screenshot(self, path: Path, *, full_page: bool = True) -> Path:
        """PNG of the page (the whole document height with ``full_page``)."""
        params: dict[str, Any] = {"format": "png", "captureBeyondViewport": full_page}
        if full_page:
            size = self.page("Page.getLayoutMetrics")["cssContentSize"]
            params["clip"] = {
                "x": 0,
                "y": 0,
                "width": size["width"],
                "height": size["height"],
                "scale": 1,
            }
        data = self.page("Page.captureScreenshot", **params)["data"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))
        return path

    def external_requests(self, origin: str) -> list[str]:
        """URLs the page asked for outside ``origin`` (nor data:/blob:/about:) that the browser
        did not refuse to send (see :attr:`blocked_urls`)."""
        local = (origin, "data:", "blob:", "about:")
        blocked = set(self.blocked_urls)
        return [u for u in self.requested_urls if not u.startswith(local) and u not in blocked]

    def close(self) -> None:
        try:
            self._send({"id": 0, "method": "Browser.close", "params": {}})
            self.proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait(timeout=10)
        for fd in (self._to_browser_w, self._from_browser_r):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
