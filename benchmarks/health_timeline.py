"""The demo's calibration-health timeline (issue 47): when the sensor changed, when the service
marked the version in service stale, when the retrained version went into service, and the
error on new data across the span.

Runs ``orbitcal demo --dir DIR`` (the service on SQLite, Swarm A for two days at 0.1 Hz, the sensor
parameters changing half-way, one-hour uploads), then reads the service's own records (the
``health_points`` and ``calibrations`` tables of its database) and writes

- ``benchmarks/results/health_timeline.png``: RMS of the version in service on each upload's new
  samples against the sample time, by version, with the true change and the alarm marked;
- ``benchmarks/results/health_timeline.md``: the timeline, the demo's own printout, the machine.

Usage: ``python benchmarks/health_timeline.py [--seed 2020] [--out benchmarks/results]``
"""

from __future__ import annotations

import argparse
import json
import platform
import sqlite3
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _run_demo(workdir: Path, seed: int) -> tuple[str, float]:
    cmd = [sys.executable, "-m", "orbitcal", "demo", "--dir", str(workdir), "--seed", str(seed)]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=1800)
    if done.returncode != 0:
        raise SystemExit(f"the demo failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    return done.stdout, time.perf_counter() - t0


def _read(db: Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    con = sqlite3.connect(db)
    con.row_factory = sqlite3.Row
    points = [
        dict(r)
        for r in con.execute(
            "SELECT version, kind, start_us, end_us, n, rms_nt, noise_nt, ref_rms_nt, cusum, "
            "stale, change_at_us, created_at FROM health_points ORDER BY end_us, pk"
        )
    ]
    versions = []
    for r in con.execute(
        "SELECT version, status, created_at, holdout_rms_nt, provenance FROM calibrations "
        "ORDER BY version"
    ):
        prov = json.loads(r["provenance"])
        versions.append(
            {
                "version": r["version"],
                "status": r["status"],
                "created_at": r["created_at"],
                "holdout_rms_nt": r["holdout_rms_nt"],
                "data_start": prov["data"]["start"],
                "data_end": prov["data"]["end"],
                "trigger": prov.get("trigger"),
            }
        )
    con.close()
    return points, versions


def _change_from_printout(text: str) -> float:
    marker = "sensor parameters change at "
    stamp = text[text.index(marker) + len(marker) :].split("Z")[0]
    return datetime.fromisoformat(stamp + "+00:00").timestamp()


def _plot(points: list[dict[str, Any]], change_s: float, alarm: dict[str, Any], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = min(float(p["end_us"]) for p in points) / 1e6
    fig, ax = plt.subplots(figsize=(10, 4.2), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for v in sorted({int(p["version"]) for p in points}):
        mine = [p for p in points if p["version"] == v]
        x = [(float(p["end_us"]) / 1e6 - t0) / 3600.0 for p in mine]
        y = [float(p["rms_nt"]) for p in mine]
        ax.plot(x, y, "o-", ms=4, lw=1, color=colours[v % len(colours)], label=f"version {v}")
        stale = [(xi, yi) for xi, yi, p in zip(x, y, mine, strict=True) if p["stale"]]
        if stale:
            ax.plot(*zip(*stale, strict=True), "s", ms=8, mfc="none", mec="red", mew=1.5)
    noise = [(float(p["end_us"]) / 1e6 - t0) / 3600.0 for p in points]
    ax.plot(noise, [float(p["noise_nt"] or "nan") for p in points], ":", color="grey",
            label="white-noise floor of each batch")  # fmt: skip
    ax.axvline((change_s - t0) / 3600.0, color="red", lw=1, ls="--", label="sensor change (truth)")
    alarm_h = (float(alarm["end_us"]) / 1e6 - t0) / 3600.0
    ax.annotate("marked stale\n(red squares)", (alarm_h, float(alarm["rms_nt"])),
                xytext=(alarm_h + 2, float(alarm["rms_nt"]) * 0.5), fontsize=9,
                arrowprops={"arrowstyle": "->"})  # fmt: skip
    ax.set_yscale("log")
    ax.set_xlabel(f"sample time [h] from {_iso(t0)} (end of each scored upload)")
    ax.set_ylabel("RMS b_cal − b_ref on the upload's new samples [nT]")
    ax.set_title("orbitcal demo: the calibration in service against each upload's new data")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center left")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=2020)
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = p.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="orbitcal-health-"))
    printout, seconds = _run_demo(workdir, args.seed)
    points, versions = _read(workdir / "orbitcal.sqlite")
    change_s = _change_from_printout(printout)
    alarm = next(p for p in points if p["change_at_us"] is not None)
    stale_v = int(alarm["version"])
    nxt = min(
        (v for v in versions if int(v["version"]) > stale_v and v["status"] != "rejected"),
        key=lambda v: int(v["version"]),
    )
    before = [float(p["rms_nt"]) for p in points if p["kind"] == "new" and not p["stale"]
              and p["version"] == stale_v]  # fmt: skip
    stale = [float(p["rms_nt"]) for p in points if p["stale"]]
    after = [
        float(p["rms_nt"]) for p in points if p["kind"] == "new" and int(p["version"]) > stale_v
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    png = args.out / "health_timeline.png"
    _plot(points, change_s, alarm, png)
    rows = [
        ("sensor parameters change (simulation truth)", _iso(change_s), "–"),
        (
            f"version {stale_v} marked stale (the upload of samples "
            f"{_iso(float(alarm['start_us']) / 1e6)[11:]}.."
            f"{_iso(float(alarm['end_us']) / 1e6)[11:]})",
            f"change_at {_iso(float(alarm['change_at_us']) / 1e6)}",
            _iso(float(alarm["created_at"])),
        ),
        (
            f"version {nxt['version']} in service (trigger: {nxt['trigger']}; fitted on "
            f"{str(nxt['data_start'])[:19]}Z..{str(nxt['data_end'])[11:19]}Z)",
            str(nxt["data_end"])[:19] + "Z (its last sample)",
            f"{_iso(float(nxt['created_at']))} "
            f"(+{float(nxt['created_at']) - float(alarm['created_at']):.1f} s)",
        ),
    ]
    md = [
        "# The demo's calibration-health timeline (issue 47)",
        "",
        f"`python benchmarks/health_timeline.py --seed {args.seed}` on {platform.node()} "
        f"({platform.machine()}, {platform.python_version()}), {_iso(time.time())}; the demo took "
        f"{seconds:.0f} s of wall time for two simulated days.",
        "",
        "| event | sample time | wall clock (service) |",
        "|---|---|---|",
        *[f"| {a} | {b} | {c} |" for a, b, c in rows],
        "",
        f"Error of the version in service on each upload's new samples: before the change "
        f"{min(before):.2f}–{max(before):.2f} nT (version {stale_v}, held out "
        f"{float(alarm['ref_rms_nt']):.2f} nT); version {stale_v} after the change "
        f"{min(stale):.0f}–{max(stale):.0f} nT ({len(stale)} upload(s) scored stale); "
        f"afterwards {min(after):.2f}–{max(after):.2f} nT ({len(after)} uploads).",
        "",
        "![health timeline](health_timeline.png)",
        "",
        "The demo's printout:",
        "",
        "```",
        printout.rstrip(),
        "```",
        "",
    ]
    (args.out / "health_timeline.md").write_text("\n".join(md))
    print("\n".join(md[:12]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
