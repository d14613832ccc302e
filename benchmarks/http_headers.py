"""How the HTTP parsers' cost grows with the size of one header value (issue 24).

Serves a trivial ASGI app with uvicorn's ``httptools`` and ``h11`` implementations (the h11 buffer
limit raised so that it parses the whole header, as httptools does) and sends one request whose
``X-Pad`` header is 1, 2, 4, 8 and 16 MiB, written in 64 KiB pieces as a client on a socket does.
Prints the seconds until the answer and the ratio of each size's time to the previous size's:
~2 means linear cost, ~4 quadratic; then the rate of small requests on one keep-alive connection
(what h11, pure Python, costs per ordinary request against httptools).

    python benchmarks/http_headers.py
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time

APP = """
import uvicorn, sys
async def app(scope, receive, send):
    if scope["type"] != "http":
        return
    await send({"type": "http.response.start", "status": 200,
                "headers": [(b"content-length", b"2")]})
    await send({"type": "http.response.body", "body": b"ok"})
uvicorn.run(app, host="127.0.0.1", port=int(sys.argv[1]), http=sys.argv[2],
            h11_max_incomplete_event_size=1 << 30, log_level="error")
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _one(port: int, header_bytes: int) -> float:
    piece = b"a" * 65536
    t0 = time.perf_counter()
    with socket.create_connection(("127.0.0.1", port), timeout=600) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nX-Pad: ")
        for _ in range(header_bytes // len(piece)):
            s.sendall(piece)
        s.sendall(b"\r\n\r\n")
        s.recv(100)
    return time.perf_counter() - t0


def _small_requests_per_s(port: int, n: int = 2000) -> float:
    """Sequential keep-alive GETs with ordinary headers: the per-request cost of the parser."""
    request = b"GET / HTTP/1.1\r\nHost: x\r\nX-API-Key: " + b"k" * 48 + b"\r\n\r\n"
    with socket.create_connection(("127.0.0.1", port), timeout=60) as s:
        t0 = time.perf_counter()
        for _ in range(n):
            s.sendall(request)
            answer = b""
            while not answer.endswith(b"ok"):
                answer += s.recv(4096)
        return n / (time.perf_counter() - t0)


def main() -> None:
    sizes_mib = (1, 2, 4, 8, 16)
    for impl in ("httptools", "h11"):
        port = _free_port()
        proc = subprocess.Popen([sys.executable, "-c", APP, str(port), impl])
        try:
            for _ in range(100):
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    break
                except OSError:
                    time.sleep(0.1)
            previous = None
            for mib in sizes_mib:
                seconds = _one(port, mib << 20)
                ratio = "" if previous is None else f"  x{seconds / previous:.1f}"
                print(f"{impl:9s} {mib:2d} MiB header: {seconds:7.3f} s{ratio}", flush=True)
                previous = seconds
            rate = _small_requests_per_s(port)
            print(f"{impl:9s} small requests: {rate:7.0f} /s (one keep-alive connection)")
        finally:
            proc.terminate()
            proc.wait()


if __name__ == "__main__":
    main()
