"""The HTTP server's own limits: what uvicorn is told, and what it cannot be told.

uvicorn's default HTTP implementation (httptools) reads a header value whole, whatever its size,
and its cost grows faster than linearly with it (``benchmarks/http_headers.py``: ×3.3 per doubling
from 4 to 8 MiB, against ×2 for h11); it has no header-read or body-read timeout, and without
``timeout_graceful_shutdown`` a client trickling an upload keeps a SIGTERMed server alive. So the
service runs on h11 (linear: its buffer search resumes where it stopped) through
:class:`LimitedH11Protocol`, a small subclass that adds, per connection:

* **header size**: the request line and headers may hold ``max_header_bytes``; beyond, the
  answer is 431 and nothing more is read (h11's own buffer limit stays above it as a backstop);
* **header timeout**: a connection must deliver a request's headers within ``header_timeout_s`` of
  opening (or of the request's first byte on a kept-alive connection); half-open connections
  are closed, partial headers answered 408;
* **body timeouts**: a body may pause at most ``body_idle_timeout_s`` between two pieces (while
  the server is reading) and take ``body_timeout_s`` in all; the request is then cut with 408 and
  the application sees a client disconnect, so nothing of it is stored;
* **shutdown**: on SIGTERM uploads still arriving get half of ``shutdown_timeout_s`` to finish,
  then are cut with 503; uvicorn's ``timeout_graceful_shutdown`` cancels whatever still runs at
  the full deadline.

The header *count* limit is checked by :class:`HeaderCount` (ASGI, so it holds under any server).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import re
from dataclasses import dataclass
from typing import Any, ClassVar

import h11
from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.settings import Settings

__all__ = ["HeaderCount", "HttpLimits", "LimitedH11Protocol", "uvicorn_options"]

log = logging.getLogger("orbitcal.service.http")

#: The end of a header block (h11 accepts bare LF line ends too).
_BLANK_LINE = re.compile(rb"\n\r?\n")
#: After answering a cut request, how long its remainder is read and dropped before closing [s].
LINGER_S = 2.0


@dataclass(frozen=True)
class HttpLimits:
    """The server's limits (``docs/reliability.md``); see :class:`service.settings.Settings`."""

    max_header_bytes: int = 64 * 1024
    max_header_count: int = 100
    header_timeout_s: float = 10.0
    body_idle_timeout_s: float = 30.0
    body_timeout_s: float = 600.0
    shutdown_timeout_s: float = 10.0
    max_connections: int = 1000

    @classmethod
    def from_settings(cls, settings: Settings) -> HttpLimits:
        return cls(
            max_header_bytes=settings.max_header_bytes,
            max_header_count=settings.max_header_count,
            header_timeout_s=settings.header_timeout_s,
            body_idle_timeout_s=settings.body_idle_timeout_s,
            body_timeout_s=settings.body_timeout_s,
            shutdown_timeout_s=settings.shutdown_timeout_s,
            max_connections=settings.max_connections,
        )


def _raw_response(status: int, reason: str, detail: str) -> bytes:
    body = json.dumps({"detail": detail, "errors": []}).encode()
    head = (
        f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\n"
        f"content-length: {len(body)}\r\nconnection: close\r\n\r\n"
    )
    return head.encode("ascii") + body


class LimitedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with header size and read timeouts, and a shutdown deadline.

    The limits are a class attribute (uvicorn builds one protocol per connection from the class):
    set by :func:`uvicorn_options`, or read from the ``ORBITCAL_*`` environment in a worker
    process that uvicorn spawned.
    """

    limits: ClassVar[HttpLimits | None] = None

    @classmethod
    def _limits(cls) -> HttpLimits:
        if cls.limits is None:
            cls.limits = HttpLimits.from_settings(Settings())
        return cls.limits

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._lim = self._limits()
        self._header_bytes = 0
        self._header_timer: asyncio.TimerHandle | None = None
        self._body_idle_timer: asyncio.TimerHandle | None = None
        self._body_deadline: asyncio.TimerHandle | None = None
        self._shutdown_timer: asyncio.TimerHandle | None = None
        self._discarding = False
        self._tail = b""  # the last bytes of the header block so far (a blank line may straddle)
        self._arm_header_timer()

    # --- timers ------------------------------------------------------------------------------

    def _arm_header_timer(self) -> None:
        if self._header_timer is None:
            self._header_timer = self.loop.call_later(
                self._lim.header_timeout_s, self._on_header_timeout
            )

    def _cancel(self, *names: str) -> None:
        for name in names:
            timer = getattr(self, name)
            if timer is not None:
                timer.cancel()
                setattr(self, name, None)

    def _on_header_timeout(self) -> None:
        self._header_timer = None
        if self.conn.their_state is not h11.IDLE or self.transport.is_closing():
            return
        if self._header_bytes == 0:
            log.info("idle connection closed", extra={"client": self._who()})
            self.transport.close()
            return
        self._cut(
            408,
            "Request Timeout",
            f"request headers not complete within {self._lim.header_timeout_s:g} s",
        )

    def _on_body_idle(self) -> None:
        self._body_idle_timer = None
        if self.conn.their_state is not h11.SEND_BODY or self.transport.is_closing():
            return
        if self.flow.read_paused:  # we stopped reading, not the client: wait for the app
            self._body_idle_timer = self.loop.call_later(
                self._lim.body_idle_timeout_s, self._on_body_idle
            )
            return
        self._cut(
            408,
            "Request Timeout",
            f"request body: no data for {self._lim.body_idle_timeout_s:g} s; nothing was stored",
        )

    def _on_body_deadline(self) -> None:
        self._body_deadline = None
        if self.conn.their_state is h11.SEND_BODY and not self.transport.is_closing():
            self._cut(
                408,
                "Request Timeout",
                f"request body not complete within {self._lim.body_timeout_s:g} s; "
                "nothing was stored",
            )

    def _on_shutdown_deadline(self) -> None:
        self._shutdown_timer = None
        if self.conn.their_state is h11.SEND_BODY and not self.transport.is_closing():
            self._cut(
                503,
                "Service Unavailable",
                "server shutting down before the request body was complete; nothing was "
                "stored, re-send it",
            )

    # --- cutting a request -------------------------------------------------------------------

    def _who(self) -> str:
        return f"{self.client[0]}:{self.client[1]}" if self.client else "?"

    def _cut(self, status: int, reason: str, detail: str) -> None:
        """Answer ``status`` (unless an answer has started) and close; the app sees a disconnect."""
        cycle = self.cycle
        started = cycle is not None and not cycle.response_complete and cycle.response_started
        log.info(
            "request cut",
            extra={"status": status, "reason": detail, "client": self._who()},
        )
        if cycle is not None and not cycle.response_complete:
            cycle.disconnected = True
            cycle.message_event.set()
        self._cancel("_header_timer", "_body_idle_timer", "_body_deadline", "_shutdown_timer")
        if started or self.transport.is_closing():
            self.transport.close()
            return
        # Answer, half-close, and discard what still arrives for a moment before closing: a
        # close with unread data makes the kernel send RST, and the client would lose the
        # answer (the "lingering close" of nginx and Apache).
        self.transport.write(_raw_response(status, reason, detail))
        self._discarding = True
        if self.transport.can_write_eof():
            self.transport.write_eof()
        self.loop.call_later(LINGER_S, self.transport.close)

    # --- uvicorn's protocol interface --------------------------------------------------------

    def data_received(self, data: bytes) -> None:
        if self._discarding:  # a cut request's remainder: read and dropped until the close
            return
        awaiting_headers = self.conn.their_state is h11.IDLE
        if awaiting_headers:
            # Measured before h11 sees the bytes, so that an oversized header block is refused
            # even when it arrives whole in one read (the search is linear in what arrives).
            self._arm_header_timer()
            window = self._tail + data
            end = _BLANK_LINE.search(window)
            head = len(data) if end is None else end.end() - len(self._tail)
            if self._header_bytes + head > self._lim.max_header_bytes:
                self._cut(
                    431,
                    "Request Header Fields Too Large",
                    f"request line and headers exceed {self._lim.max_header_bytes} bytes",
                )
                return
            self._header_bytes += head
            self._tail = window[-2:]
        super().data_received(data)
        if self.transport.is_closing():
            return
        state = self.conn.their_state
        if state is h11.IDLE:
            return
        if awaiting_headers:  # the headers are complete
            self._header_bytes = 0
            self._tail = b""
            self._cancel("_header_timer")
        if state is h11.SEND_BODY:
            self._cancel("_body_idle_timer")
            self._body_idle_timer = self.loop.call_later(
                self._lim.body_idle_timeout_s, self._on_body_idle
            )
            if self._body_deadline is None:
                self._body_deadline = self.loop.call_later(
                    self._lim.body_timeout_s, self._on_body_deadline
                )
        else:
            self._cancel("_body_idle_timer", "_body_deadline")

    def on_response_complete(self) -> None:
        self._cancel("_body_idle_timer", "_body_deadline", "_shutdown_timer")
        super().on_response_complete()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel("_header_timer", "_body_idle_timer", "_body_deadline", "_shutdown_timer")
        super().connection_lost(exc)

    def shutdown(self) -> None:
        if (
            self.cycle is not None
            and not self.cycle.response_complete
            and self.conn.their_state is h11.SEND_BODY
            and self._shutdown_timer is None
        ):
            self._shutdown_timer = self.loop.call_later(
                self._lim.shutdown_timeout_s / 2, self._on_shutdown_deadline
            )
        super().shutdown()


class HeaderCount:
    """431 for a request with more than ``limit`` header fields (ASGI middleware)."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and len(scope.get("headers", ())) > self.limit:
            body = json.dumps(
                {"detail": f"more than {self.limit} request header fields", "errors": []}
            ).encode()
            await send(
                {
                    "type": "http.response.start",
                    "status": 431,
                    "headers": [
                        (b"content-type", b"application/json"),
                        (b"content-length", str(len(body)).encode()),
                        (b"connection", b"close"),
                    ],
                }
            )
            await send({"type": "http.response.body", "body": body})
            return
        await self.app(scope, receive, send)


def uvicorn_options(settings: Settings) -> dict[str, Any]:
    """The keyword arguments of ``uvicorn.run`` that carry the server's limits."""
    limits = HttpLimits.from_settings(settings)
    LimitedH11Protocol.limits = limits
    return {
        "http": LimitedH11Protocol,
        # h11 refuses a header block beyond this itself (400); ours answers 431 first
        "h11_max_incomplete_event_size": limits.max_header_bytes + (1 << 20),
        "timeout_graceful_shutdown": max(1, math.ceil(limits.shutdown_timeout_s)),
        "limit_concurrency": limits.max_connections,
        # the app applies ORBITCAL_FORWARDED_ALLOW_IPS itself (service.app), so that the same
        # setting holds under any server; uvicorn's own default would trust 127.0.0.1
        "proxy_headers": False,
    }
