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

Executors: ``--executor processes`` (default) runs K ``multiprocessing`` processes calling
:func:`service.jobs.run_retrain` on their share of the job list. ``--executor celery`` is the
deployed path: the jobs are sent through the service's :class:`service.celery_app.CeleryRunner` to
the broker (``--broker``, Redis by default) and K real ``orbitcal worker --concurrency 1``
processes (the operator's command, each a Celery solo-pool worker) consume them; the per-retraining
times, the span and the throughput are then read from the job records (``started_at`` /
``finished_at``) and each worker's peak RSS from ``/proc``. The Celery mode needs a database every
worker process can open: by default a fresh schema in the PostgreSQL at ``--pg`` (created and
dropped by the run), or ``--database URL``.

Usage: ``python benchmarks/fleet.py [--spacecraft 1000] [--workers 1 2]
[--methods linear lmbp-hk] [--executor processes|celery] [--broker URL] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing as mp
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
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


def _peak_rss_mb(pid: int) -> tuple[float, float]:
    """``(current, peak)`` resident set size of a live process [MB], from ``/proc``."""
    fields = {}
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                fields[key] = float(value.split()[0]) / 1024.0
    return fields.get("VmRSS", float("nan")), fields.get("VmHWM", float("nan"))


def _cpu_s(pid: int) -> float:
    """User + system CPU time of a live process [s], from ``/proc``."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _job_records(url: str, jobs: list[str]) -> list[tuple[str, float | None, float | None]]:
    """``(status, started_at, finished_at)`` of each job, from the database."""
    import sqlalchemy as sa

    from service.storage import Job, make_engine, read_tx

    engine = make_engine(url)
    with read_tx(engine) as conn:
        rows = conn.execute(
            sa.select(Job.status, Job.started_at, Job.finished_at).where(Job.id.in_(jobs))
        ).all()
    engine.dispose()
    return [(str(r[0]), r[1], r[2]) for r in rows]


def run_celery(
    url: str, broker_url: str, method: str, jobs: list[str], workers: int, timeout_s: float
) -> dict[str, Any]:
    """Send ``jobs`` through the service's Celery runner and consume them with ``workers`` real
    ``orbitcal worker --concurrency 1`` processes; times come from the job records."""
    from service.celery_app import TASK_NAME, CeleryRunner
    from service.settings import Settings

    queue = "orbitcal-fleet-" + uuid.uuid4().hex[:8]  # a queue of its own on a shared broker
    settings = Settings(
        database_url=url, job_backend="celery", broker_url=broker_url, queue=queue, method=method
    )
    app = CeleryRunner(settings).app
    for job_id in jobs:  # what CeleryRunner.submit sends, synchronously here
        app.send_task(TASK_NAME, args=[job_id], queue=queue)
    env = {
        **os.environ,
        "ORBITCAL_DATABASE_URL": url,
        "ORBITCAL_BROKER_URL": broker_url,
        "ORBITCAL_QUEUE": queue,
        "ORBITCAL_LOG_LEVEL": "WARNING",
    }
    cmd = [sys.executable, "-m", "orbitcal", "worker", "--concurrency", "1"]
    t0 = time.perf_counter()
    # worker stderr, shown if a worker dies; closed in the finally below
    logs = [tempfile.TemporaryFile() for _ in range(workers)]  # noqa: SIM115
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=log) for log in logs]
    rss = []
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            records = _job_records(url, jobs)
            if all(r[0] in ("succeeded", "failed") for r in records):
                break
            for p, log in zip(procs, logs, strict=True):
                if p.poll() is not None:
                    log.seek(0)
                    tail = log.read().decode(errors="replace")[-2000:]
                    raise RuntimeError(f"a Celery worker exited with {p.returncode}:\n{tail}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(jobs)} jobs not done in {timeout_s} s")
            time.sleep(0.5)
        wall = time.perf_counter() - t0
        rss = [_peak_rss_mb(p.pid) for p in procs]
        cpu_s = sum(_cpu_s(p.pid) for p in procs)  # start-up included
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=10)
        for log in logs:
            log.close()
    started = np.array([r[1] for r in records], dtype=float)
    finished = np.array([r[2] for r in records], dtype=float)
    times = finished - started
    busy = float(np.nanmax(finished) - np.nanmin(started))
    statuses = [r[0] for r in records]
    return {
        "workers": workers,
        "n": len(jobs),
        "wall_s": wall,
        "per_job_median_s": float(np.nanmedian(times)),
        "per_job_p95_s": float(np.nanpercentile(times, 95)),
        "per_job_pct_s": [float(np.nanpercentile(times, q)) for q in (10, 50, 90, 99, 100)],
        "method": method,
        "jobs_s": busy,
        "throughput_per_s": len(jobs) / busy,
        "succeeded": statuses.count("succeeded"),
        "worker_cpu_s": cpu_s,
        # worker RSS when idle after its last job, and its peak
        "maxrss_mb": max(r[1] for r in rss),
        "rss_before_mb": max(r[0] for r in rss),
    }


@contextlib.contextmanager
def _pg_schema(pg_url: str) -> Iterator[str]:
    """A fresh PostgreSQL schema for this run (dropped afterwards); yields its URL."""
    import sqlalchemy as sa

    from service.storage import make_engine

    schema = "fleet_" + uuid.uuid4().hex[:12]
    admin = make_engine(pg_url)
    with admin.begin() as conn:
        conn.execute(sa.text(f"CREATE SCHEMA {schema}"))
    sep = "&" if "?" in pg_url else "?"
    try:
        yield f"{pg_url}{sep}options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(sa.text(f"DROP SCHEMA IF EXISTS {schema} CASCADE"))
        admin.dispose()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacecraft", type=int, default=1000)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--methods", nargs="+", default=["linear", "lmbp-hk"])
    ap.add_argument("--database", help="SQLAlchemy URL (default: a SQLite file in a temp dir)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--executor",
        choices=("processes", "celery"),
        default="processes",
        help="multiprocessing workers calling run_retrain, or real `orbitcal worker` processes",
    )
    ap.add_argument("--broker", default="redis://127.0.0.1:6379/0", help="Celery broker URL")
    ap.add_argument(
        "--pg",
        default="postgresql://postgres@127.0.0.1:5432/test",
        help="PostgreSQL for the celery executor's own schema (when --database is not given)",
    )
    ap.add_argument("--timeout", type=float, default=3600.0, help="per celery run [s]")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    with contextlib.ExitStack() as stack:
        if args.database:
            url, db_name = args.database, "given URL"
        elif args.executor == "celery":
            url, db_name = stack.enter_context(_pg_schema(args.pg)), "PostgreSQL (own schema)"
        else:
            tmp = Path(tempfile.mkdtemp(prefix="orbitcal-fleet-"))
            url, db_name = f"sqlite:///{tmp / 'fleet.sqlite'}", "SQLite (WAL)"
        _bench(args, url, db_name)


def _bench(args: argparse.Namespace, url: str, db_name: str) -> None:
    load_before = os.getloadavg()[0]

    def execute(method: str, jobs: list[str], workers: int) -> dict[str, Any]:
        if args.executor == "celery":
            return run_celery(url, args.broker, method, jobs, workers, args.timeout)
        return run(url, method, jobs, workers)

    t0 = time.perf_counter()
    jobs = _setup(url, args.spacecraft, args.seed)
    setup_s = time.perf_counter() - t0
    print(f"setup: {setup_s:.1f} s", flush=True)
    rows: list[dict[str, Any]] = []
    for method in args.methods:
        if rows:
            jobs = _new_jobs(url, method)
        r = execute(method, jobs, 1)
        r["kind"] = "first calibration" if not rows else "first retraining with this method"
        r["load"] = os.getloadavg()[0]
        rows.append(r)
        print(r, flush=True)
        for workers in args.workers:
            # the same workload for each worker count: the whole fleet against its champion
            r = execute(method, _new_jobs(url, method), workers)
            r["kind"] = "retraining vs champion"
            r["load"] = os.getloadavg()[0]
            rows.append(r)
            print(r, flush=True)
    executor = (
        f"Celery: `orbitcal worker --concurrency 1` processes, broker {args.broker}"
        if args.executor == "celery"
        else "multiprocessing worker processes calling run_retrain"
    )
    lines = [
        f"machine: {platform.machine()}, {os.cpu_count()} cores, shared; 1-min load average "
        f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after; Python "
        f"{platform.python_version()}; database {db_name}; executor {executor}",
        f"fleet: {args.spacecraft} spacecraft × 1 day at 0.1 Hz ({int(DAY_S / CADENCE_S)} samples "
        f"each), methods {', '.join(args.methods)}, IGRF-14, TLE propagated per retraining",
        "",
        f"setup (simulation and bulk insert of {args.spacecraft * int(DAY_S / CADENCE_S):,} "
        f"samples): {setup_s:.0f} s",
        "",
        "| method | run | worker processes | spacecraft | succeeded | jobs span [s] "
        "| per retraining p10 / p50 / p90 / p99 / max [s] | retrainings/s "
        f"| RSS per worker {'at the end' if args.executor == 'celery' else 'after imports'} "
        "/ peak [MB] | load after | worker CPU [s] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        pct = " / ".join(f"{x:.3f}" for x in r["per_job_pct_s"])
        lines.append(
            f"| {r['method']} | {r['kind']} | {r['workers']} | {r['n']} | {r['succeeded']} "
            f"| {r['jobs_s']:.1f} | {pct} | {r['throughput_per_s']:.2f} "
            f"| {r['rss_before_mb']:.0f} / {r['maxrss_mb']:.0f} | {r['load']:.1f} "
            f"| {r.get('worker_cpu_s', float('nan')):.1f} |"
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
