"""What scoring every upload costs ingest (issue 47), side by side in one run.

Two spacecraft on one service (SQLite, in this process, a real uvicorn on loopback): ``plain`` has
no calibration, so its uploads are only parsed, validated and committed; ``scored`` has one in
service, so each upload is also scored against it after the commit (reference field along the new
samples, the full calibration applied, the change rule). Uploads alternate between the two, the
same table shapes (Parquet, with quaternions, positions from the TLE), at each batch size. Two
figures each: the median request time (scoring runs after the answer, in the service's health
thread) and the total time of a run of uploads until their health is read (``GET …/health``
waits for the scoring still running: the whole cost, answer and scoring).

Usage: ``python benchmarks/health_ingest_cost.py [--repeats 15] [--out benchmarks/results]``
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "api"))

from service_helpers import ADMIN_KEY, live_server, sqlite_settings
from service_worlds import SWARM_A_TLE, T0_UTC_S, world


def _post(c: httpx.Client, sc: str, df: object) -> float:
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)  # type: ignore[attr-defined]
    t0 = time.perf_counter()
    r = c.post(
        f"/v1/spacecraft/{sc}/telemetry",
        content=buf.getvalue(),
        headers={"content-type": "application/vnd.apache.parquet"},
    )
    dt = time.perf_counter() - t0
    assert r.status_code == 200, r.text
    return dt


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=15)
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="orbitcal-health-cost-"))
    lines = []
    with (
        live_server(sqlite_settings(tmp, window_s=30 * 86400.0)) as server,
        server.client(ADMIN_KEY) as c,
    ):
        for sc in ("plain", "scored"):
            assert c.post("/v1/spacecraft", json={"id": sc, "tle": SWARM_A_TLE}).is_success
        first, _ = world(T0_UTC_S, 2000, positions=False)
        _post(c, "scored", first)
        job = c.post("/v1/spacecraft/scored/calibrations").json()["job_id"]
        while c.get(f"/v1/jobs/{job}").json()["status"] not in ("succeeded", "failed"):
            time.sleep(0.1)
        t = T0_UTC_S + 20000.0
        for n in (360, 3600, 20000):
            times: dict[str, list[float]] = {"plain": [], "scored": []}
            totals = {"plain": 0.0, "scored": 0.0}
            tables = []
            for k in range(args.repeats):
                tables.append(world(t, n, positions=False, seed=k)[0])
                t += 10.0 * n
            for rnd in range(2):  # plain then scored, then scored then plain
                for sc in ("plain", "scored") if rnd == 0 else ("scored", "plain"):
                    half = tables[rnd::2]
                    t0 = time.perf_counter()
                    for df in half:
                        times[sc].append(_post(c, sc, df))
                    assert c.get(f"/v1/spacecraft/{sc}/health").status_code in (200, 404)
                    totals[sc] += time.perf_counter() - t0
            plain, scored = (statistics.median(times[s]) for s in ("plain", "scored"))
            per = {s: totals[s] / len(times[s]) for s in totals}
            lines.append(
                f"| {n} | {1e3 * plain:.1f} | {1e3 * scored:.1f} | {scored / plain:.2f} | "
                f"{1e3 * per['plain']:.1f} | {1e3 * per['scored']:.1f} | "
                f"{per['scored'] / per['plain']:.2f} |"
            )
            print(lines[-1], flush=True)
        points = len(c.get("/v1/spacecraft/scored/health/series?limit=100000").json())
    md = [
        "# Ingest with and without health scoring (issue 47)",
        "",
        f"`python benchmarks/health_ingest_cost.py --repeats {args.repeats}` on {platform.node()} "
        f"({platform.machine()}, Python {platform.python_version()}, 2 cores shared), "
        f"{time.strftime('%Y-%m-%dT%H:%MZ', time.gmtime())}. Median request time of a Parquet "
        "upload (with quaternions; positions from the TLE) to a spacecraft without a calibration "
        "(`plain`: parse, validate, commit) and to one with a `linear` calibration in service "
        "(`scored`: the same, then the new samples scored against it, after the answer); "
        '"whole": per upload, a run of uploads until `GET …/health` has their scores; '
        f"{points} health points were recorded. Load average at the end "
        f"{', '.join(f'{x:.1f}' for x in os.getloadavg())} (other work on the machine: the "
        "ratios move by ±0.5 from run to run; run it on a quiet machine to quote them).",
        "",
        "| samples per upload | answer, plain [ms] | answer, scored [ms] | ratio "
        "| whole, plain [ms] | whole, scored [ms] | ratio |",
        "|---|---|---|---|---|---|---|",
        *lines,
        "",
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "health_ingest_cost.md").write_text("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
