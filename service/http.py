"""The HTTP server's own limits: what uvicorn is told, and what it cannot be told.

uvicorn's HTTP implementations have no header-size limit that holds as the bytes arrive, no
header-read or body-read timeout, and without ``timeout_graceful_shutdown`` a client trickling an
upload keeps a SIGTERMed server alive. httptools (uvicorn's default) also reads a header value
whole and its cost grows faster than linearly with it (``benchmarks/http_headers.py``: ×3.3 per
doubling from 4 to 8 MiB, against ×2 for h11). The service therefore runs on one of two
subclasses of uvicorn's protocols, chosen by ``ORBITCAL_HTTP_PROTOCOL``:

* :class:`LimitedHttpToolsProtocol` (``httptools``, the default): the C parser, half of h11's
  server CPU per request (``benchmarks/results/load_reads.md``); the header limit below is enforced
  before a byte reaches the parser, so its quadratic path is never taken;
* :class:`LimitedH11Protocol` (``h11``): pure Python, linear in what it buffers.

Both get the same limits from :class:`EdgeLimits` (the logic is written once), per connection:

* **header size**: the request line and headers may hold ``max_header_bytes``, counted as the
  bytes arrive, before the parser sees them; beyond, the answer is 431 and nothing more is read
  (h11's own buffer limit stays above it as a backstop);
* **header timeout**: a connection must deliver a request's headers within ``header_timeout_s`` of
  opening (or of the request's first byte on a kept-alive connection); half-open connections
  are closed, partial headers answered 408;
* **body timeouts**: a body may pause at most ``body_idle_timeout_s`` between two pieces (while
  the server is reading) and take ``body_timeout_s`` in all; the request is then cut with 408 and
  the application sees a client disconnect, so nothing of it is stored;
* **shutdown**: on SIGTERM uploads still arriving get half of ``shutdown_timeout_s`` to finish,
  then are cut with 503; uvicorn's ``timeout_graceful_shutdown`` cancels whatever still runs at
  the full deadline.

The header *count* and the request's *framing* (``Transfer-Encoding`` beside ``Content-Length``,
a ``Content-Length`` that is not one number: 400 and the connection closed) are checked by
:class:`HeaderChecks` (ASGI, so they hold under any server; httptools refuses both itself, h11
served them).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import re
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import h11
from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from service.settings import Settings

__all__ = [
    "EdgeLimits",
    "HeaderChecks",
    "HttpLimits",
    "LimitedH11Protocol",
    "LimitedHttpToolsProtocol",
    "protocol_class",
    "uvicorn_options",
]

log = logging.getLogger("orbitcal.service.http")

#: The end of a header block (both parsers accept bare LF line ends too).
_BLANK_LINE = re.compile(rb"\n\r?\n")
#: After answering a cut request, how long its remainder is read and dropped before closing [s].
LINGER_S = 2.0
#: Where a connection's current request is, as the limits see it.
Phase = Literal["headers", "body", "done"]


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


class EdgeLimits:
    """The limits of ``docs/reliability.md`` for any of uvicorn's HTTP/1.1 protocols (a mixin).

    A subclass says where its parser is (:meth:`_phase`); everything else is here. The limits are
    a class attribute (uvicorn builds one protocol per connection from the class): set by
    :func:`uvicorn_options`, or read from the ``ORBITCAL_*`` environment in a worker process
    that uvicorn spawned.
    """

    limits: ClassVar[HttpLimits | None] = None
    # provided by uvicorn's protocol classes
    transport: asyncio.Transport
    loop: asyncio.AbstractEventLoop
    cycle: Any
    flow: Any
    client: tuple[str, int] | None

    @classmethod
    def _limits(cls) -> HttpLimits:
        if cls.limits is None:
            cls.limits = HttpLimits.from_settings(Settings())
        return cls.limits

    def _phase(self) -> Phase:
        """'headers' while a request's headers may be arriving, 'body' while its body is read."""
        raise NotImplementedError

    def connection_made(self, transport: asyncio.Transport) -> None:
        super().connection_made(transport)  # type: ignore[misc]
        self._lim = self._limits()
        self._header_bytes = 0
        # when the pending request's headers began: the connection's opening, then each
        # kept-alive request's first byte; None while no request's headers are pending
        self._header_since: float | None = self.loop.time()
        self._header_timer: asyncio.TimerHandle | None = None
        self._body_idle_timer: asyncio.TimerHandle | None = None
        self._body_deadline: asyncio.TimerHandle | None = None
        self._shutdown_timer: asyncio.TimerHandle | None = None
        self._discarding = False
        self._tail = b""  # the last bytes of the header block so far (a blank line may straddle)
        self._arm_header_timer(self._lim.header_timeout_s)

    # --- timers ------------------------------------------------------------------------------

    def _arm_header_timer(self, delay_s: float) -> None:
        # One timer per connection, moved on when it fires early, instead of one per request
        # (a timer set and cancelled per request cost a measurable part of a small GET).
        self._header_timer = self.loop.call_later(delay_s, self._on_header_timeout)

    def _cancel(self, *names: str) -> None:
        for name in names:
            timer = getattr(self, name)
            if timer is not None:
                timer.cancel()
                setattr(self, name, None)

    def _on_header_timeout(self) -> None:
        self._header_timer = None
        if self.transport.is_closing():
            return
        since = self._header_since
        if since is None or self._phase() != "headers":  # no headers pending: look again later
            self._arm_header_timer(self._lim.header_timeout_s)
            return
        left_s = since + self._lim.header_timeout_s - self.loop.time()
        if left_s > 0:
            self._arm_header_timer(left_s)
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
        if self._phase() != "body" or self.transport.is_closing():
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
        if self._phase() == "body" and not self.transport.is_closing():
            self._cut(
                408,
                "Request Timeout",
                f"request body not complete within {self._lim.body_timeout_s:g} s; "
                "nothing was stored",
            )

    def _on_shutdown_deadline(self) -> None:
        self._shutdown_timer = None
        if self._phase() == "body" and not self.transport.is_closing():
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
        awaiting_headers = self._phase() == "headers"
        if awaiting_headers and not self._count_header_bytes(data):
            return
        super().data_received(data)  # type: ignore[misc]
        if self.transport.is_closing():
            return
        phase = self._phase()
        if phase == "headers":
            return
        if awaiting_headers:  # the headers are complete
            self._header_bytes = 0
            self._tail = b""
            self._header_since = None
        if phase == "body":
            self._cancel("_body_idle_timer")
            self._body_idle_timer = self.loop.call_later(
                self._lim.body_idle_timeout_s, self._on_body_idle
            )
            if self._body_deadline is None:
                self._body_deadline = self.loop.call_later(
                    self._lim.body_timeout_s, self._on_body_deadline
                )
        elif self._body_idle_timer is not None or self._body_deadline is not None:
            self._cancel("_body_idle_timer", "_body_deadline")

    def _count_header_bytes(self, data: bytes) -> bool:
        """Count ``data``'s part of the header block; False (and 431 sent) beyond the limit.

        Measured before the parser sees the bytes, so that an oversized header block is refused
        even when it arrives whole in one read (the search is linear in what arrives).
        """
        if self._header_since is None:  # a kept-alive connection's next request begins
            self._header_since = self.loop.time()
        window = self._tail + data
        end = _BLANK_LINE.search(window)
        head = len(data) if end is None else end.end() - len(self._tail)
        if self._header_bytes + head > self._lim.max_header_bytes:
            self._cut(
                431,
                "Request Header Fields Too Large",
                f"request line and headers exceed {self._lim.max_header_bytes} bytes",
            )
            return False
        self._header_bytes += head
        self._tail = window[-2:]
        return True

    def on_response_complete(self) -> None:
        if self._body_idle_timer or self._body_deadline or self._shutdown_timer:
            self._cancel("_body_idle_timer", "_body_deadline", "_shutdown_timer")
        super().on_response_complete()  # type: ignore[misc]

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel("_header_timer", "_body_idle_timer", "_body_deadline", "_shutdown_timer")
        super().connection_lost(exc)  # type: ignore[misc]

    def shutdown(self) -> None:
        if (
            self.cycle is not None
            and not self.cycle.response_complete
            and self._phase() == "body"
            and self._shutdown_timer is None
        ):
            self._shutdown_timer = self.loop.call_later(
                self._lim.shutdown_timeout_s / 2, self._on_shutdown_deadline
            )
        super().shutdown()  # type: ignore[misc]


class LimitedH11Protocol(EdgeLimits, H11Protocol):  # type: ignore[misc]
    """uvicorn's h11 protocol with the limits of :class:`EdgeLimits`."""

    def _phase(self) -> Phase:
        state = self.conn.their_state
        if state is h11.IDLE:
            return "headers"
        return "body" if state is h11.SEND_BODY else "done"


class LimitedHttpToolsProtocol(EdgeLimits, HttpToolsProtocol):  # type: ignore[misc]
    """uvicorn's httptools protocol with the limits of :class:`EdgeLimits`.

    httptools keeps no state one can ask, so the parser's callbacks record it: 'headers' from
    the connection (and each message's first byte) to the end of the headers, 'body' until the
    message is complete, 'done' until its answer is (then 'headers' again, as h11's next cycle).
    A request pipelined behind another in one read is counted from the next read on (the
    slack is one read, at most 256 KiB, fed to the parser in one piece: linear).
    """

    _state: Phase = "headers"

    def _phase(self) -> Phase:
        return self._state

    def on_message_begin(self) -> None:
        self._state = "headers"
        super().on_message_begin()

    def on_headers_complete(self) -> None:
        self._state = "body"
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        self._state = "done"
        super().on_message_complete()

    def on_response_complete(self) -> None:
        if self._state == "done":
            self._state = "headers"
        super().on_response_complete()


#: ``ORBITCAL_HTTP_PROTOCOL`` → the protocol class.
PROTOCOLS: dict[str, type[EdgeLimits]] = {
    "httptools": LimitedHttpToolsProtocol,
    "h11": LimitedH11Protocol,
}


def protocol_class(name: str) -> type[EdgeLimits]:
    """The protocol class of ``ORBITCAL_HTTP_PROTOCOL`` (``httptools`` or ``h11``)."""
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise ValueError(f"unknown HTTP protocol {name!r}: one of {sorted(PROTOCOLS)}") from None


def _refusal(status: int, detail: str) -> tuple[dict[str, Any], dict[str, Any]]:
    body = json.dumps({"detail": detail, "errors": []}).encode()
    start = {
        "type": "http.response.start",
        "status": status,
        "headers": [
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
            (b"connection", b"close"),
        ],
    }
    return start, {"type": "http.response.body", "body": body}


def framing_error(headers: Any) -> str | None:
    """Why a request's body framing is ambiguous (RFC 9112 §6.3), or None.

    ``Transfer-Encoding`` beside ``Content-Length`` (a proxy in front may frame the body by the
    other one: request smuggling), or a ``Content-Length`` that is not exactly one decimal
    number (``5, 5``, two fields).
    """
    lengths = [v for k, v in headers if k == b"content-length"]
    if lengths and any(k == b"transfer-encoding" for k, _ in headers):
        return "Transfer-Encoding and Content-Length both given: the body's length is ambiguous"
    if len(lengths) > 1 or (lengths and not lengths[0].strip().isdigit()):
        return "Content-Length must be one decimal number"
    return None


class HeaderChecks:
    """431 beyond ``limit`` header fields; 400 for an ambiguous body framing (ASGI middleware).

    Both answers close the connection (``connection: close``): nothing after such a request on
    the same connection is read as a request.
    """

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            headers = scope.get("headers", ())
            refusal = None
            if len(headers) > self.limit:
                refusal = _refusal(431, f"more than {self.limit} request header fields")
            elif (why := framing_error(headers)) is not None:
                log.info("request refused", extra={"status": 400, "reason": why})
                refusal = _refusal(400, why)
            if refusal is not None:
                await send(refusal[0])
                await send(refusal[1])
                return
        await self.app(scope, receive, send)


def uvicorn_options(settings: Settings) -> dict[str, Any]:
    """The keyword arguments of ``uvicorn.run`` (or ``uvicorn.Config``) that carry the limits."""
    limits = HttpLimits.from_settings(settings)
    protocol = protocol_class(settings.http_protocol)
    protocol.limits = limits
    return {
        "http": protocol,
        # h11 refuses a header block beyond this itself (400); ours answers 431 first
        "h11_max_incomplete_event_size": limits.max_header_bytes + (1 << 20),
        "timeout_graceful_shutdown": max(1, math.ceil(limits.shutdown_timeout_s)),
        "limit_concurrency": limits.max_connections,
        # the app applies ORBITCAL_FORWARDED_ALLOW_IPS itself (service.app), so that the same
        # setting holds under any server; uvicorn's own default would trust 127.0.0.1
        "proxy_headers": False,
    }
