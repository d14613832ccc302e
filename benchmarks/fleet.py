"""Fleet retraining benchmark: N spacecraft × one day at 0.1 Hz, retrained by the service's job
function (:func:`service.jobs.run_retrain`, the same code the Celery workers run).

Worlds are simulated with :mod:`orbitcal.simulate` on real TLEs (Swarm A, B, C and the ISS from
``tests/authorities/swarm_iss_real_tles.tle``); each spacecraft gets its own random sensor
(Wang 2020 spread) applied to one of these worlds' reference fields, so generation stays cheap
while every retraining does the full work: read the window from the database, propagate the TLE,
evaluate IGRF-14 along track and in the body frame, fit, score challenger and champion on the
held-out block, write the new version.

Workers: ``--workers K`` runs K processes pulling jobs (as K Celery worker processes would);
time per spacecraft, throughput and peak memory per worker process are reported, with the
projected time for the fleet on N workers.

Methods: ``--methods linear lmbp-hk``: per method, a first calibration of the whole fleet, then
the same workload (every spacecraft retrained against its champion) with each ``--workers``
count in turn, so the scale-out from one to two worker processes is measured on identical jobs.
The per-retraining cost distribution (p10, median, p90, p99, max) is reported per run.

Usage: ``python benchmarks/fleet.py [--spacecraft 1000] [--workers 1 2]
[--methods linear lmbp-hk] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import platform
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TLE_FILE = REPO / "tests" / "authorities" / "swarm_iss_real_tles.tle"
NORAD = (39452, 39451, 39453, 25544)
DAY_S = 86400.0
CADENCE_S = 10.0


def _setup(url: str, n: int, seed: int) -> list[str]:
    """Create the fleet in the database; return the job ids (one queued retraining each)."""
    import sqlalchemy as sa

    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import Tumbling, select_tle, simulate_world
    from orbitcal.telemetry import Telemetry
    from service.ingest import telemetry_to_rows
    from service.jobs import create_job
    from service.settings import Settings
    from service.storage import Spacecraft, insert_samples, make_engine, upgrade, write_tx

    engine = make_engine(url, sqlite_synchronous="NORMAL")
    upgrade(engine)
    settings = Settings(database_url=url, method="linear", window_s=DAY_S)
    text = TLE_FILE.read_text()
    rng = np.random.default_rng(seed)
    worlds = []
    for norad in NORAD:
        tle = select_tle(text, norad_id=norad)
        start = float(np.floor(tle.epoch_utc_s / DAY_S) * DAY_S)
        w = simulate_world(
            tle,
            start_utc_s=start,
            duration_s=DAY_S,
            cadence_s=CADENCE_S,
            rng=rng,
            attitude=Tumbling(rate_body_deg_s=(0.05, -0.08, 0.11)),
        )
        worlds.append((tle, w))
    jobs = []
    for i in range(n):
        tle, w = worlds[i % len(worlds)]
        sensor = SensorModel.random(rng=rng)
        b_raw = sensor.measure(w.b_ref_body_nt, rng=rng)
        tel = Telemetry(t_utc_s=w.telemetry.t_utc_s, b_raw_nt=b_raw, q_wxyz=w.telemetry.q_wxyz)
        sc_id = f"sc-{i:05d}"
        with write_tx(engine) as conn:
            conn.execute(
                sa.insert(Spacecraft).values(
                    id=sc_id,
                    tle=tle.text,
                    attitude_frame="GCRS",
                    created_at=time.time(),
                    sample_count=0,
                    samples_at_last_job=0,
                )
            )
            pk = conn.execute(sa.select(Spacecraft.pk).where(Spacecraft.id == sc_id)).scalar_one()
            insert_samples(conn, pk, telemetry_to_rows(pk, tel))
        job_id, _ = create_job(engine, settings, pk, trigger="benchmark")
        jobs.append(job_id)
    engine.dispose()
    return jobs


def _new_jobs(url: str, method: str) -> list[str]:
    import sqlalchemy as sa

    from service.jobs import create_job
    from service.settings import Settings
    from service.storage import Spacecraft, make_engine, read_tx

    engine = make_engine(url)
    settings = Settings(database_url=url, method=method, window_s=DAY_S)
    with read_tx(engine) as conn:
        pks = conn.execute(sa.select(Spacecraft.pk).order_by(Spacecraft.pk)).scalars().all()
    jobs = [create_job(engine, settings, pk, trigger="benchmark")[0] for pk in pks]
    engine.dispose()
    return jobs


def _worker(url: str, method: str, job_ids: list[str], out: Any) -> None:
    import torch

    torch.set_num_threads(1)
    from service.jobs import run_retrain
    from service.settings import Settings
    from service.storage import make_engine

    engine = make_engine(url, sqlite_synchronous="NORMAL")
    settings = Settings(database_url=url, method=method, window_s=DAY_S)
    import orbitcal.pipeline  # noqa: F401  (imports are not part of a job's cost)

    rss_before_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    times = []
    statuses = []
    start = time.time()
    for job_id in job_ids:
        t0 = time.perf_counter()
        statuses.append(run_retrain(engine, settings, job_id))
        times.append(time.perf_counter() - t0)
    end = time.time()
    maxrss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    out.put((times, statuses, maxrss_mb, rss_before_mb, start, end))


def run(url: str, method: str, jobs: list[str], workers: int) -> dict[str, Any]:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    shares = [jobs[k::workers] for k in range(workers)]
    procs = [ctx.Process(target=_worker, args=(url, method, s, q)) for s in shares]
    t0 = time.perf_counter()
    for p in procs:
        p.start()
    results = [q.get() for _ in procs]
    for p in procs:
        p.join()
    wall = time.perf_counter() - t0
    busy = max(r[5] for r in results) - min(r[4] for r in results)
    times = np.concatenate([np.array(r[0]) for r in results])
    statuses = [s for r in results for s in r[1]]
    return {
        "workers": workers,
        "n": len(jobs),
        "wall_s": wall,
        "per_job_median_s": float(np.median(times)),
        "per_job_p95_s": float(np.percentile(times, 95)),
        "per_job_pct_s": [float(np.percentile(times, q)) for q in (10, 50, 90, 99, 100)],
        "method": method,
        "jobs_s": busy,
        "throughput_per_s": len(jobs) / busy,
        "succeeded": statuses.count("succeeded"),
        "maxrss_mb": max(r[2] for r in results),
        "rss_before_mb": max(r[3] for r in results),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacecraft", type=int, default=1000)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--methods", nargs="+", default=["linear", "lmbp-hk"])
    ap.add_argument("--database", help="SQLAlchemy URL (default: a SQLite file in a temp dir)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    load_before = os.getloadavg()[0]
    if args.database:
        url = args.database
    else:
        url = f"sqlite:///{Path(tempfile.mkdtemp(prefix='orbitcal-fleet-')) / 'fleet.sqlite'}"
    t0 = time.perf_counter()
    jobs = _setup(url, args.spacecraft, args.seed)
    setup_s = time.perf_counter() - t0
    print(f"setup: {setup_s:.1f} s", flush=True)
    rows = []
    for method in args.methods:
        if rows:
            jobs = _new_jobs(url, method)
        r = run(url, method, jobs, 1)
        r["kind"] = "first calibration" if not rows else "first retraining with this method"
        rows.append(r)
        print(r, flush=True)
        for workers in args.workers:
            # the same workload for each worker count: the whole fleet against its champion
            r = run(url, method, _new_jobs(url, method), workers)
            r["kind"] = "retraining vs champion"
            rows.append(r)
            print(r, flush=True)
    lines = [
        f"machine: {platform.machine()}, {os.cpu_count()} cores, shared; 1-min load average "
        f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after; Python "
        f"{platform.python_version()}; database "
        f"{'SQLite (WAL)' if not args.database else 'given URL'}",
        f"fleet: {args.spacecraft} spacecraft × 1 day at 0.1 Hz ({int(DAY_S / CADENCE_S)} samples "
        f"each), methods {', '.join(args.methods)}, IGRF-14, TLE propagated per retraining",
        "",
        f"setup (simulation and bulk insert of {args.spacecraft * int(DAY_S / CADENCE_S):,} "
        f"samples): {setup_s:.0f} s",
        "",
        "| method | run | worker processes | spacecraft | succeeded | jobs span [s] "
        "| per retraining p10 / p50 / p90 / p99 / max [s] | retrainings/s "
        "| RSS per worker after imports / peak [MB] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        pct = " / ".join(f"{x:.3f}" for x in r["per_job_pct_s"])
        lines.append(
            f"| {r['method']} | {r['kind']} | {r['workers']} | {r['n']} | {r['succeeded']} "
            f"| {r['jobs_s']:.1f} | {pct} | {r['throughput_per_s']:.2f} "
            f"| {r['rss_before_mb']:.0f} / {r['maxrss_mb']:.0f} |"
        )
    for method in args.methods:
        same = [r for r in rows if r["method"] == method and r["kind"] == "retraining vs champion"]
        if len(same) >= 2:
            lines.append(
                f"\nscale-out, {method}: {same[0]['workers']} -> {same[-1]['workers']} worker "
                f"processes, {same[-1]['throughput_per_s'] / same[0]['throughput_per_s']:.2f}× "
                "the retrainings per second on the same jobs"
            )
    best = max(rows, key=lambda r: r["throughput_per_s"])
    per_core = best["per_job_median_s"]
    lines += [
        "",
        f"Projection (CPU-bound, {per_core:.3f} s per retraining per worker process, "
        "one core each): a fleet of 1,000 spacecraft retrained daily needs "
        f"{1000 * per_core / 60:.1f} CPU-minutes per day; with N Celery worker processes on "
        f"separate cores the fleet takes about {1000 * per_core:.0f}/N s "
        f"(N = 4: {1000 * per_core / 4:.0f} s, N = 16: {1000 * per_core / 16:.0f} s), until the "
        "database's write rate (one small transaction per retraining) becomes the limit.",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
