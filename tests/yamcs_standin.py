"""A stand-in for a Yamcs processor's parameter endpoints on loopback (issue 21 tests).

It implements the two endpoints ``yamcs-push`` uses, ``POST /api/processors/{instance}/
{processor}/parameters:batchGet`` and ``:batchSet`` (yamcs-api ``processing.proto``), checks HTTP
Basic credentials and the payload shape (``NamedObjectId`` and a typed ``Value``, as Yamcs's
protobuf-JSON mapping reads them) and keeps the values it was given.
"""

from __future__ import annotations

import base64
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from orbitcal.export import ExportOptions, calibration_form, product_info
from orbitcal.export.xtce import coefficient_values

PREFIX = "/api/processors/magsat/realtime/parameters:"
VALUE_FIELDS = {"DOUBLE": "doubleValue", "UINT32": "uint32Value", "STRING": "stringValue"}


class FakeYamcs:
    """The parameters of a Yamcs processor, as an HTTP server on 127.0.0.1."""

    def __init__(self, parameters: dict[str, Any], *, user: str, password: str) -> None:
        self.parameters = dict(parameters)  # qualified name -> value
        self.auth = "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()
        self.requests: list[tuple[str, Any]] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args: Any) -> None:
                pass

            def _answer(self, code: int, body: Any = None) -> None:
                data = b"" if body is None else json.dumps(body).encode()
                self.send_response(code)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def do_POST(self) -> None:
                if self.headers.get("Authorization") != outer.auth:
                    return self._answer(401, {"code": 401, "msg": "unauthorized"})
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                outer.requests.append((self.path, body))
                if self.path == PREFIX + "batchGet":
                    return self._answer(200, outer.batch_get(body))
                if self.path == PREFIX + "batchSet":
                    problem = outer.batch_set(body)
                    return self._answer(400, {"msg": problem}) if problem else self._answer(200, {})
                return self._answer(404, {"msg": f"no route {self.path}"})

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"

    def batch_get(self, body: dict[str, Any]) -> dict[str, Any]:
        assert set(body) <= {"id", "fromCache", "timeout"}
        out = []
        for ident in body["id"]:
            name = ident["name"]
            if name in self.parameters:
                v = self.parameters[name]
                kind = (
                    "STRING" if isinstance(v, str) else "UINT32" if isinstance(v, int) else "DOUBLE"
                )
                out.append(
                    {"id": {"name": name}, "engValue": {"type": kind, VALUE_FIELDS[kind]: v}}
                )
        return {"value": out}

    def batch_set(self, body: dict[str, Any]) -> str | None:
        """Check the shape like Yamcs's protobuf-JSON mapping would, then store."""
        if set(body) != {"request"}:
            return f"unexpected fields {sorted(body)}"
        staged = {}
        for req in body["request"]:
            if set(req) != {"id", "value"} or set(req["id"]) != {"name"}:
                return f"bad request entry {req}"
            name, value = req["id"]["name"], req["value"]
            if name not in self.parameters:
                return f"no parameter {name}"
            field = VALUE_FIELDS.get(value.get("type"))
            if field is None or set(value) != {"type", field}:
                return f"bad value {value}"
            staged[name] = value[field]
        self.parameters.update(staged)
        return None

    def __enter__(self) -> FakeYamcs:
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.server.shutdown()
        self.server.server_close()


def mdb_of(doc: dict[str, Any]) -> dict[str, Any]:
    """The local parameters of an MDB loaded from this document's XTCE, at their initial values."""
    opts = ExportOptions(format="xtce")
    values = coefficient_values(calibration_form(doc), product_info(doc), opts)
    return {f"/MAGCAL/{k}": v for k, v in values.items()}
