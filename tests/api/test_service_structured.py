"""Arrays and objects in telemetry cells, through the real HTTP ingest (issue 44 item 6).

Every column of the table holds one scalar (a number, a time, a text flag). A JSON array or
object in any cell — housekeeping, field, time — is refused for its row with a reason naming the
column and the kind of value; one whose serialised size passes the text limit
(``max_string_chars``) is a 413 for the upload, exactly as a text cell of that size is. Nothing
is stored as the Python text of a list, and a rejection's reason never echoes the value.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from service_helpers import LiveServer
from service_worlds import SWARM_A_TLE, T0_UTC_S, world

from orbitcal.telemetry.limits import DEFAULT_LIMITS

LIMIT = DEFAULT_LIMITS.max_string_chars
BIG = [1] * (LIMIT // 2 + 1)  # serialised as "[1,1,…]": just over the limit
CASES: dict[str, tuple[str, Any]] = {
    "housekeeping array": ("hk_v", [1, 2, 3]),
    "housekeeping object": ("hk_v", {"a": {"b": 1}}),
    "housekeeping empty array": ("hk_v", []),
    "field array": ("b_x", [20_000.0]),
    "field object": ("b_y", {"value": 1.0}),
    "time array": ("time", ["2022-08-01T00:00:00Z"]),
    "quaternion array": ("q_w", [1.0, 0.0, 0.0, 0.0]),
    "housekeeping array at the text limit": ("hk_v", [7] * (LIMIT // 2 - 1)),
}
OVER: dict[str, tuple[str, Any]] = {
    "housekeeping array over the text limit": ("hk_v", BIG),
    "housekeeping object over the text limit": ("hk_v", {"k": "x" * LIMIT}),
    "time array over the text limit": ("time", BIG),
    "housekeeping text over the text limit": ("hk_v", "x" * (LIMIT + 1)),
}


def _records(column: str, value: Any) -> list[dict[str, Any]]:
    df, _ = world(T0_UTC_S, 20)
    df["hk_v"] = "nominal"
    records: list[dict[str, Any]] = json.loads(df.to_json(orient="records"))
    for r, t in zip(records, df["time"], strict=True):
        r["time"] = t if isinstance(t, str) else float(t)
    records[3][column] = value
    return records


def _post(c: Any, sc: str, records: list[dict[str, Any]], fmt: str) -> Any:
    if fmt == "ndjson":
        body = "\n".join(json.dumps(r) for r in records)
        ctype = "application/x-ndjson"
    else:
        body, ctype = json.dumps(records), "application/json"
    return c.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers={"content-type": ctype})


@pytest.mark.parametrize("fmt", ["ndjson", "json"])
def test_structured_cells_are_refused_per_row_or_held_to_the_text_limit(
    server: LiveServer, tmp_path: Path, fmt: str
) -> None:
    with server.client() as c:
        for k, (case, (column, value)) in enumerate({**CASES, **OVER}.items()):
            sc = f"sc-{fmt}-{k}"
            assert c.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE}).status_code == 201
            r = _post(c, sc, _records(column, value), fmt)
            if case in OVER:
                assert r.status_code == 413, (case, r.status_code, r.text[:300])
                detail = r.json()["detail"]
                assert f"row 3: {column} holds" in detail and "max_string_chars" in detail, detail
                assert len(r.text) < 1000
                continue
            assert r.status_code == 200, (case, r.text[:300])
            body = r.json()
            assert body["accepted"] == 19 and len(body["rejected"]) == 1, (case, body)
            reason = body["rejected"][0]
            assert reason["row"] == 3, (case, body)
            kind = "object" if isinstance(value, dict) else "array"
            assert reason["reason"].startswith(f"{column} holds a JSON {kind} of "), reason
            assert len(reason["reason"]) < 120, reason  # the value is not echoed
    # Nothing stored is the text of a list: every stored housekeeping value is a scalar.
    with sqlite3.connect(tmp_path / "orbitcal.sqlite") as db:
        stored = [json.loads(h) for (h,) in db.execute("SELECT hk FROM samples") if h]
    values = [v for h in stored for v in h.values()]
    assert values and all(isinstance(v, str | int | float) for v in values), values[:5]
    assert not any(isinstance(v, str) and v.startswith(("[", "{")) for v in values)
