"""Diagnose timing: ``orbitcal diagnose`` against ``orbitcal calibrate --method linear`` as whole
processes on the same telemetry, in turn (diagnose, linear, diagnose, ...).

Run:  python benchmarks/diagnose_timing.py DIR [--repeats 2] [--out PATH]

``DIR`` comes from ``orbitcal simulate`` (telemetry.csv and spacecraft.tle), e.g. one day at 1 Hz
on a real Swarm A TLE. Reported per pair: wall and CPU seconds of each process and the peak
resident memory of the diagnosis process (``ru_maxrss`` of the child), with the load average.
Issue 15 asks for diagnose ≤ 4× the linear calibration and ≤ 600 MB at 86,400 samples.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "diagnose_timing.md"


def _run(cmd: list[str]) -> tuple[float, float, float]:
    """Wall [s], CPU [s] and peak RSS [MB] of one whole child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"{cmd[3]} failed with status {status}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world", type=Path)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    tel, tle = str(args.world / "telemetry.csv"), str(args.world / "spacecraft.tle")
    base = [sys.executable, "-m", "orbitcal"]
    diag = [*base, "diagnose", tel, "--tle", tle, "--out", os.devnull]
    lin = [*base, "calibrate", tel, "--tle", tle, "--method", "linear", "--quiet"]
    lin += ["--out", os.devnull]
    load0 = os.getloadavg()
    rows = []
    for _ in range(args.repeats):
        d, c = _run(diag), _run(lin)
        rows.append((d, c))
        print(d, c, flush=True)
    n = Path(tel).read_text().count("\n") - 1
    wall = [d[0] / c[0] for d, c in rows]
    cpu = [d[1] / c[1] for d, c in rows]
    lines = [
        "# Diagnose timing (`benchmarks/diagnose_timing.py`)",
        "",
        f"World `{args.world.name}`: {n:,} samples. Whole processes in turn, {args.repeats} pairs. "
        f"Load average {' '.join(f'{x:.2f}' for x in load0)} at start, "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at end; nproc {os.cpu_count()}.",
        "",
        "| pair | diagnose wall / cpu [s] | linear wall / cpu [s] | diagnose / linear wall "
        "| cpu | diagnose peak RSS [MB] |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for i, (d, c) in enumerate(rows):
        lines.append(
            f"| {i + 1} | {d[0]:.1f} / {d[1]:.1f} | {c[0]:.1f} / {c[1]:.1f} | {d[0] / c[0]:.2f} "
            f"| {d[1] / c[1]:.2f} | {d[2]:.0f} |"
        )
    lines += ["", f"Median ratio: wall {np.median(wall):.2f}×, cpu {np.median(cpu):.2f}×.", ""]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
