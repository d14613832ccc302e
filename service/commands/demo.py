"""``orbitcal demo``: the main job on the embedded default, end to end, in a temporary directory.

Starts the HTTP service on SQLite (in-process scheduler, authentication on with a fresh admin
key), simulates Swarm A on a real TLE for two days at 0.1 Hz with a sensor parameter change after
the first day (as in Wang et al. 2020), streams the telemetry over HTTP in one-hour batches
(CSV, Parquet, CCSDS packets, NDJSON in turn), lets the scheduler retrain, and prints the
calibration versions and where to look.
"""

from __future__ import annotations

import argparse
import io
import secrets
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "demo",
        help="run the service on SQLite with a simulated spacecraft streaming telemetry",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--days", type=float, default=2.0, help="simulated span [days] (default 2)")
    p.add_argument(
        "--method",
        default="lmbp-hk",
        help="calibration method (default lmbp-hk: the LM-trained BP network with housekeeping "
        "inputs and a linear path)",
    )
    p.add_argument("--seed", type=int, default=2020, help="simulation seed")
    p.add_argument("--port", type=int, default=0, help="port (default: any free port)")
    p.add_argument("--dir", metavar="DIR", help="keep the database here (default: a temp dir)")
    p.add_argument(
        "--keep-serving",
        action="store_true",
        help="keep the service running after the demo (Ctrl-C stops it)",
    )
    p.set_defaults(func=run)


def _batches(world: Any, rows_per_batch: int) -> list[tuple[bytes, str]]:
    """The telemetry in consecutive batches, cycling through the ingest formats."""
    import pandas as pd

    from orbitcal import ccsds

    tel = world.telemetry
    n = len(tel.t_utc_s)
    out = []
    for k, start in enumerate(range(0, n, rows_per_batch)):
        sl = slice(start, min(n, start + rows_per_batch))
        t = tel.t_utc_s[sl]
        b = tel.b_raw_nt[sl]
        q = tel.q_wxyz[sl]
        kind = k % 4
        if kind == 2:
            out.append((ccsds.encode_packets(t, b, q_wxyz=q), "application/vnd.ccsds.space-packet"))
            continue
        df = pd.DataFrame(
            {
                "time": t,
                **{f"b_{a}": b[:, i] for i, a in enumerate("xyz")},
                **{f"q_{a}": q[:, i] for i, a in enumerate("wxyz")},
            }
        )
        if kind == 0:
            out.append((df.to_csv(index=False).encode(), "text/csv"))
        elif kind == 1:
            buf = io.BytesIO()
            df.to_parquet(buf, index=False)
            out.append((buf.getvalue(), "application/vnd.apache.parquet"))
        else:
            text = df.to_json(orient="records", lines=True, double_precision=15)
            out.append((text.encode(), "application/x-ndjson"))
    return out


@dataclass
class DemoWorld:
    """The simulated spacecraft: its element set, telemetry, truth and sensor."""

    tle: Any
    world: Any
    sensor: Any
    t_change_utc_s: float
    batches: list[tuple[bytes, str]]


@dataclass
class RunningService:
    """The service in a thread of this process, on a free port of 127.0.0.1."""

    server: Any
    thread: threading.Thread
    url: str

    def stop(self) -> bool:
        """Stop it; False when it did not stop within 30 s."""
        self.server.should_exit = True
        self.thread.join(timeout=30)
        return not self.thread.is_alive()


#: Why the version history differs from run to run (printed under the version table).
TIMING_NOTE = (
    "  Which uploads each version saw depends on when the scheduler's ticks fell between them "
    "(wall-clock\n  time on this machine), so the number of versions can differ from run to "
    "run; the version in\n  service at the end, fitted on the latest 6 h, does not."
)


def _settings(args: argparse.Namespace, db: Path, admin_key: str) -> Any:
    from pydantic import SecretStr

    from service.settings import Settings

    return Settings(
        database_url=f"sqlite:///{db}",
        admin_key=SecretStr(admin_key),
        bind_host="127.0.0.1",
        method=args.method,
        window_s=6 * 3600.0,  # sliding window: the latest 6 h of data
        min_new_samples=1800,  # retrain after 5 h of new data...
        cadence_s=2.0,  # ...at most every 2 s of wall time (simulated time runs fast)
        scheduler_tick_s=0.5,
        log_level="WARNING",
    )


def _simulate(args: argparse.Namespace) -> DemoWorld:
    """Swarm A on its real CelesTrak set of 2022-08-01 (orbitcal/data, provenance in its README),
    tumbling, with a sensor parameter change half-way (as in Wang et al. 2020)."""
    import numpy as np

    from orbitcal.data import real_tles_text
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import Tumbling, make_effect, select_tle, simulate_world

    tle = select_tle(real_tles_text(), norad_id=39452, at_utc_s=1659398400.0)
    start = float(np.floor(tle.epoch_utc_s / 86400.0) * 86400.0)
    rng = np.random.default_rng(args.seed)
    sensor = SensorModel.random(rng=rng)
    change_at = 0.5
    step = make_effect(
        "parameter_drift",
        step_nt=(300.0, -220.0, 150.0),
        trend_nt_per_day=(0.0, 0.0, 0.0),
        scale_step=(0.01, -0.008, 0.006),
        step_at_fraction=change_at,
    )
    world = simulate_world(
        tle,
        start_utc_s=start,
        duration_s=args.days * 86400.0,
        cadence_s=10.0,
        rng=rng,
        attitude=Tumbling(rate_body_deg_s=(0.05, -0.08, 0.11)),
        sensor=sensor,
        effects=[step],
        seed=args.seed,
    )
    t_all = world.telemetry.t_utc_s
    t_change = float(t_all[0] + change_at * (t_all[-1] - t_all[0]))
    return DemoWorld(tle, world, sensor, t_change, _batches(world, rows_per_batch=360))


def _start_service(settings: Any, port: int) -> RunningService:
    import uvicorn

    from orbitcal.cli import CliError
    from service.app import create_app
    from service.http import uvicorn_options

    # the limits and the shutdown deadline of `orbitcal serve` (without them uvicorn waits for
    # every connection and request to end, however long the clients keep it busy)
    config = uvicorn.Config(
        create_app(settings),
        host="127.0.0.1",
        port=port,
        log_level="warning",
        **uvicorn_options(settings),
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise CliError("the service did not start")
        time.sleep(0.05)
    bound = server.servers[0].sockets[0].getsockname()[1]
    return RunningService(server, thread, f"http://127.0.0.1:{bound}")


def _jobs_live(c: Any) -> bool:
    """Whether a retraining is queued or running (the service's /metrics)."""
    return any(
        line.startswith(('orbitcal_jobs{status="queued"}', 'orbitcal_jobs{status="running"}'))
        and not line.endswith(" 0.0")
        for line in c.get("/metrics").text.splitlines()
    )


def _stream(c: Any, sc: str, demo: DemoWorld, tick_s: float) -> None:
    """Register the spacecraft and upload the batches, one downlink pass at a time: after each
    the scheduler gets a tick, and a retraining it started finishes before the next upload."""
    from orbitcal.cli import CliError

    r = c.post("/v1/spacecraft", json={"id": sc, "tle": demo.tle.text})
    if r.status_code != 201:
        raise CliError(f"registering the spacecraft failed: {r.text}")
    accepted = 0
    t0 = time.perf_counter()
    for body, media in demo.batches:
        r = c.post(f"/v1/spacecraft/{sc}/telemetry", content=body, headers={"content-type": media})
        if r.status_code != 200:
            raise CliError(f"upload failed: {r.status_code} {r.text}")
        accepted += r.json()["accepted"]
        time.sleep(tick_s + 0.1)
        deadline = time.monotonic() + 120
        while _jobs_live(c) and time.monotonic() < deadline:
            time.sleep(0.1)
    # one batch again: duplicates change nothing
    body, media = demo.batches[0]
    dup = c.post(
        f"/v1/spacecraft/{sc}/telemetry", content=body, headers={"content-type": media}
    ).json()
    print(
        f"  streamed {accepted} samples in {len(demo.batches)} uploads "
        f"({time.perf_counter() - t0:.1f} s); re-sent one upload: "
        f"{dup['duplicates']} duplicates, {dup['accepted']} new"
    )


def _wait_for_the_last_data(c: Any, sc: str, demo: DemoWorld) -> None:
    """Until a calibration covers the last sample (bounded: 120 s)."""
    from orbitcal.timescales import utc_s_to_iso

    last_sample = utc_s_to_iso([float(demo.world.telemetry.t_utc_s[-1])])[0][:19]
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        jobs = [v for v in c.get(f"/v1/spacecraft/{sc}/calibrations").json() if v["job_id"]]
        if jobs and not _jobs_live(c):
            if jobs[0]["provenance"]["data"]["end"] >= last_sample:
                return
            c.post(f"/v1/spacecraft/{sc}/calibrations")
        time.sleep(0.5)


def _print_versions(
    versions: list[dict[str, Any]], served: dict[str, Any], demo: DemoWorld
) -> float:
    """The version table, with each version's RMS against the simulation's truth over the last
    6 h; returns that RMS for the version in service."""
    from orbitcal.metrics import rms_nt
    from orbitcal.pipeline import apply_document

    tel = demo.world.telemetry
    last_hours = tel.t_utc_s >= tel.t_utc_s[-1] - 6 * 3600.0
    truth = demo.world.b_ref_body_nt[last_hours]

    def rms_on_recent(doc: dict[str, Any]) -> float:
        return rms_nt(apply_document(doc, tel.select(last_hours)), truth)

    print()
    print("  version  status       data end              held-out RMS  true RMS, last 6 h  reason")
    for v in versions:
        print(
            f"  {v['version']:>7}  {v['status']:<11}  {v['provenance']['data']['end'][:19]}Z  "
            f"{v['holdout_rms_nt']:>9.2f} nT  {rms_on_recent(v['document']):>15.2f} nT  "
            f"{v['reason']}"
        )
    print(TIMING_NOTE)
    final = rms_on_recent(served)
    print()
    print(
        f"  in service: version {served['version']} ({served['method']}); against the simulation's "
        f"truth over the last 6 h it leaves {final:.2f} nT rms (sensor noise "
        f"{demo.sensor.noise_std_nt:g} nT)"
    )
    print()
    return final


def _iso_s(text: str) -> float:
    from datetime import datetime

    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def _print_health(
    series: list[dict[str, Any]], versions: list[dict[str, Any]], demo: DemoWorld
) -> None:
    """The health timeline: when the sensor changed, when the service found the version in
    service stale, when the retrained version went into service, the error on new data."""
    from orbitcal.timescales import utc_s_to_iso

    alarm = next((p for p in series if p["change_at"]), None)
    print("  calibration health (each upload's new samples scored against the version in service):")
    print(f"    sensor changed (simulation)  {utc_s_to_iso([demo.t_change_utc_s])[0][:19]}Z")
    if alarm is None:
        print("    no change found")
        return
    stale_v = alarm["version"]
    print(
        f"    version {stale_v} marked stale   by the upload of samples {alarm['start'][:19]}Z.."
        f"{alarm['end'][11:19]}Z: {alarm['rms_nt']:.1f} nT on them, {alarm['ref_rms_nt']:.2f} nT "
        f"held out; the change began at {alarm['change_at'][:19]}Z "
        f"({_iso_s(alarm['change_at']) - demo.t_change_utc_s:+.0f} s from the truth)"
    )
    after = [v for v in versions if v["version"] > stale_v and v["status"] != "rejected"]
    if after:
        first = min(after, key=lambda v: v["version"])
        wall = _iso_s(first["created_at"]) - _iso_s(alarm["scored_at"])
        print(
            f"    version {first['version']} in service     fitted on data from "
            f"{first['provenance']['data']['start'][:19]}Z to "
            f"{first['provenance']['data']['end'][:19]}Z "
            f"(after the change only), {wall:.1f} s (wall clock) after the alarm"
        )
    before = [
        p["rms_nt"]
        for p in series
        if p["kind"] == "new" and not p["stale"] and p["version"] == stale_v
    ]
    stale = [p["rms_nt"] for p in series if p["stale"]]
    later = [p["rms_nt"] for p in series if p["kind"] == "new" and p["version"] > stale_v]
    if before and stale:
        print(
            f"    error on new data            before the change "
            f"{min(before):.2f}-{max(before):.2f} nT; "
            f"version {stale_v} stale {min(stale):.0f}-{max(stale):.0f} nT"
            + (f"; after {min(later):.2f}-{max(later):.2f} nT" if later else "")
        )
    print()


def _print_where_to_look(url: str, admin_key: str, db: Path, sc: str) -> None:
    """Links a browser opens as they are, and curl lines for the routes that need the key (a
    browser cannot send the X-API-Key header)."""
    print("Where to look (serving until Ctrl-C):")
    print(f"  dashboard     {url}/dashboard#key={admin_key}")
    print("                (the key is in the URL fragment: the browser keeps it, the server never")
    print("                sees it in a URL)")
    print(
        f"  API docs      {url}/docs   (Authorize with the key below; OpenAPI {url}/openapi.json)"
    )
    print(f"  calibrations  curl -H 'X-API-Key: {admin_key}' {url}/v1/spacecraft/{sc}/calibrations")
    print(f"  metrics       curl -H 'X-API-Key: {admin_key}' {url}/metrics")
    print(f"  database      {db}")
    print("Ctrl-C stops the service.")
    sys.stdout.flush()


def run(args: argparse.Namespace) -> int:
    import httpx

    from orbitcal.cli import CliError
    from orbitcal.timescales import utc_s_to_iso

    if args.days <= 0.25:
        raise CliError("--days must be more than 0.25")
    workdir = Path(args.dir) if args.dir else Path(tempfile.mkdtemp(prefix="orbitcal-demo-"))
    workdir.mkdir(parents=True, exist_ok=True)
    db = workdir / "orbitcal.sqlite"
    admin_key = "ock_demo_" + secrets.token_urlsafe(24)
    settings = _settings(args, db, admin_key)
    demo = _simulate(args)
    service = _start_service(settings, args.port)
    # the URL only while it answers: without --keep-serving the service ends with the demo
    where = service.url if args.keep_serving else "127.0.0.1 (stops when the demo ends)"
    print(f"orbitcal demo: service on {where}; SQLite {db}")
    print(
        f"  spacecraft swarm-a on the real Swarm A TLE (NORAD {demo.tle.norad_id}, epoch "
        f"{utc_s_to_iso([demo.tle.epoch_utc_s])[0][:19]}Z); {len(demo.world.telemetry.t_utc_s)} "
        f"samples at 0.1 Hz over {args.days:g} days; sensor parameters change at "
        f"{utc_s_to_iso([demo.t_change_utc_s])[0][:19]}Z"
    )
    sc = "swarm-a"
    try:
        with httpx.Client(base_url=service.url, headers={"X-API-Key": admin_key}, timeout=60) as c:
            _stream(c, sc, demo, settings.scheduler_tick_s)
            _wait_for_the_last_data(c, sc, demo)
            versions = c.get(f"/v1/spacecraft/{sc}/calibrations").json()
            served = c.get(f"/v1/spacecraft/{sc}/calibration").json()
            series = c.get(f"/v1/spacecraft/{sc}/health/series", params={"limit": 100000}).json()
    except BaseException:
        service.stop()
        raise
    final = _print_versions(versions, served, demo)
    _print_health(series, versions, demo)
    code = 0 if final < 10.0 else 1
    if not args.keep_serving:
        service.stop()
        print(
            f"The demo service has stopped; its database is kept in {db}. Run "
            "`orbitcal demo --keep-serving` to keep the service running and open its dashboard."
        )
        sys.stdout.flush()
        return code
    try:  # Ctrl-C from the first link on stops the service cleanly
        _print_where_to_look(service.url, admin_key, db, sc)
        while service.thread.is_alive():
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    if service.stop():
        print("orbitcal demo: the service has stopped.")
    else:
        print("orbitcal demo: the service did not stop within 30 s", file=sys.stderr)
    sys.stdout.flush()
    return code
