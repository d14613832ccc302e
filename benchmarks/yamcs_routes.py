"""Benchmark (issue 45): how often a real Yamcs 5.12.8 leaves an output at the previous row's value,
by the way rows are fed.

Run:  python benchmarks/yamcs_routes.py MODE [--rows N] [--settle-s S] [--out PATH]

The suite of ``tests/test_export_yamcs_real.py`` (its mission MDB and one calibration MDB per
method × names in one instance ``suite``; Java 17 and ``fprime-yamcs-bundle``), rows of the
shared world replayed into every cell, each output compared with ``orbitcal apply`` (``*_CAL``)
and the affine part (``*_CAL_LIN``) to 1e-9 nT after waiting ``--settle-s`` seconds for it.

MODE:

- ``both``: housekeeping over REST and UDP, then the raw row over REST and UDP, without waiting
  in between (the test's feeding until issue 45 was explained): the two routes' deliveries go
  through the algorithms on two threads at once;
- ``routes``: one route at a time, the test's ``Feeder.row`` (local inputs, awaited; then the
  mission's packets, awaited);
- ``local``: the local cells only (no mission cells, no UDP), housekeeping and raw sets back to
  back without waiting: one thread.

Prints one JSON line (rows, stale rows and which outputs) and appends it to ``--out``
(default ``benchmarks/results/yamcs_routes.jsonl``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_export_yamcs_real as suite  # noqa: E402
from export_worlds import fitted as fit  # noqa: E402
from shared_worlds import swarm_a_temperature_world  # noqa: E402
from yamcs_real import METHODS, YamcsServer, write_suite_folder  # noqa: E402

from orbitcal.export import affine_part, calibration_form  # noqa: E402
from orbitcal.export import evaluate as evaluate_form  # noqa: E402


def _stale(got: dict[str, dict[str, Any]], wanted: dict[str, float]) -> list[str]:
    """The outputs not at their wanted value (1e-9 nT)."""
    return [n for n, v in wanted.items() if not abs(suite._value(got, n) - v) < suite.YAMCS_NT]


def _settled(
    feeder: suite.Feeder, got: dict[str, dict[str, Any]], wanted: dict[str, float], timeout_s: float
) -> dict[str, dict[str, Any]]:
    """Poll until every output holds its wanted value or ``timeout_s`` passes."""
    deadline = time.monotonic() + timeout_s
    while _stale(got, wanted):
        if time.monotonic() > deadline:
            break
        time.sleep(0.02)
        got = {**got, **feeder.proc.get(list(wanted))}
    return got


def run(mode: str, n_rows: int, settle_s: float) -> dict[str, Any]:
    world = swarm_a_temperature_world()
    fitted = {m: fit(world, m) for m in METHODS}
    documents = {m: f.document for m, f in fitted.items()}
    names = ("default", "custom") if mode == "local" else ("default", "custom", "qualified")
    cells = [(m, n) for m in METHODS for n in names]
    folder = Path(tempfile.mkdtemp(prefix="yamcs-routes-"))
    write_suite_folder(folder, documents, [*cells, ("linear-hk", "telemetered")])
    server = YamcsServer(folder)
    server.start(["suite"])
    try:
        feeder = suite.Feeder(server, "suite", fitted)
        f0 = fitted[METHODS[0]]
        rows = np.flatnonzero(f0.holdout)[:n_rows]
        any_hk = next(f.x_hk for f in fitted.values() if f.x_hk is not None)
        outputs: list[str] = []
        for m, n in cells:
            cal, lin = suite._outputs(m, n, calibration_form(documents[m]).hk_names)
            outputs += cal + lin
        stale_rows: list[tuple[int, list[str]]] = []
        t0 = time.monotonic()
        for i, row in enumerate(rows):
            stamp = 1e-3 * (i + 1)
            wanted: dict[str, float] = {}
            for m, n in cells:
                form, f = calibration_form(documents[m]), fitted[m]
                b = f.telemetry.b_raw_nt[row].copy()
                b[0] += stamp
                x = None if f.x_hk is None else f.x_hk[row : row + 1]
                cal, lin = suite._outputs(m, n, form.hk_names)
                wanted.update(zip(cal, evaluate_form(form, b[None, :], x)[0], strict=True))
                lin_values = evaluate_form(affine_part(form), b[None, :], x)[0]
                wanted.update(zip(lin, lin_values, strict=True))
            if mode == "routes":
                got = feeder.row(cells, any_hk[row], f0.telemetry.b_raw_nt[row], stamp, outputs)
            else:
                feeder.hk(cells, any_hk[row])
                got = {}
                for name, value in feeder.raw(cells, f0.telemetry.b_raw_nt[row], stamp).items():
                    mine = [o for o in outputs if suite._feeds(name, o)]
                    got.update(feeder.proc.wait_for({name: value}, [], mine))
            got = _settled(feeder, got, wanted, settle_s)
            stale = _stale(got, wanted)
            if stale:
                stale_rows.append((i, stale))
        return {
            "mode": mode,
            "rows": len(rows),
            "cells": len(cells),
            "settle_s": settle_s,
            "stale_rows": len(stale_rows),
            "stale": stale_rows,
            "seconds": round(time.monotonic() - t0, 1),
            "machine": platform.node(),
            "load_1min": round(os.getloadavg()[0], 2),
            "at_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    finally:
        server.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("mode", choices=["both", "routes", "local"])
    ap.add_argument("--rows", type=int, default=200)
    ap.add_argument("--settle-s", type=float, default=3.0)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/yamcs_routes.jsonl")
    args = ap.parse_args()
    result = run(args.mode, args.rows, args.settle_s)
    line = json.dumps(result)
    print(line)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("a") as out:
        out.write(line + "\n")


if __name__ == "__main__":
    main()
