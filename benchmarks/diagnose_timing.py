"""Diagnose timing: ``orbitcal diagnose`` against ``orbitcal calibrate --method linear`` as whole
processes on the same telemetry, in turn (diagnose, linear, diagnose, ...), and a week at 1 Hz.

Run:  python benchmarks/diagnose_timing.py DAY_DIR [--week WEEK_DIR] [--build] [--effect NAME]
      [--repeats 2] [--against SRC] [--out PATH]
      python benchmarks/diagnose_timing.py --readme    # the README's cost figure from the page

``DAY_DIR`` (and ``WEEK_DIR``) hold telemetry.csv and spacecraft.tle from ``orbitcal simulate``;
with ``--build`` a missing one is simulated first: one day (or seven) at 1 Hz from 2022-08-02 on
the shipped real Swarm A TLE (NORAD 39452), nadir, with the temperature effect (``--effect
magnetorquer``: the torquer effect, which the diagnosis names and models down to the noise) --
build once into /tmp and reuse. The table states the diagnosis's verdict and held-out RMS on the
day, so that a day whose effect is too weak to be named (the temperature day at its default size)
is not taken for a day with an effect in it. Reported per pair: wall and CPU seconds of each
process and the peak resident memory of the diagnosis (``ru_maxrss`` of the child), with the
load average; for the week, its wall and CPU time against seven times the median one-day
diagnosis of the same run.
With ``--against SRC`` (a directory holding another revision's ``orbitcal/``, e.g. from
``git archive REV orbitcal | tar -x -C SRC``) each pair also runs that revision's diagnosis on the
same telemetry, in turn with this one's, and the table gives this / that (issue 23: the same day
before and after a refactoring, in one session).
Issue 15 asks for diagnose <= 4x the linear calibration and <= 600 MB at 86,400 samples, and a
week that completes within 2 GB and 1.3 x 7 x the one-day time; issue 25 for the 4x on a day with
an effect in it (a temperature or torquer day).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "diagnose_timing.md"
README = Path(__file__).resolve().parents[1] / "README.md"
#: The README's diagnosis-cost figure lies between these markers (:func:`readme_figure`).
README_BEGIN = "<!-- diagnose_cost -->"
README_END = "<!-- /diagnose_cost -->"
TLE = Path(__file__).resolve().parents[1] / "orbitcal" / "data" / "swarm_iss_real_tles.tle"


def _run(cmd: list[str], src: Path | None = None) -> tuple[float, float, float]:
    """Wall [s], CPU [s] and peak RSS [MB] of one whole child process (``src``: the source tree
    it imports orbitcal from, first on its path)."""
    env = None if src is None else {**os.environ, "PYTHONPATH": str(src)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=src
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"{' '.join(cmd[3:5])} failed with status {status}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, usage.ru_maxrss / 1024.0


def _build(world: Path, days: int, effect: str) -> None:
    """Simulate ``days`` at 1 Hz on the shipped Swarm A elements into ``world``."""
    cmd = [sys.executable, "-m", "orbitcal", "simulate", "--tle", str(TLE), "--norad", "39452"]
    cmd += ["--start", "2022-08-02T00:00:00Z", "--duration-s", str(86400 * days)]
    cmd += ["--cadence-s", "1", "--effect", effect, "--out", str(world)]
    print("building", world, flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def readme_figure(page: str) -> str:
    """The README's cost figure from the timing page's newest section (its first heading): the
    median diagnose / linear ratios, and against another revision when that section has them.
    The figure is never typed (``--readme`` writes it; a test holds the README to it)."""
    lines = page.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("## "))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    section = lines[start:end]
    when = section[0].removeprefix("## ").split(":", 1)[0]
    linear = next(ln for ln in section if ln.startswith("Median ratio: wall "))
    wall, cpu = (x.strip().rstrip(".×") for x in linear.removeprefix("Median ratio: ").split(","))
    text = (
        f"{wall.removeprefix('wall ')}× `calibrate --method linear` wall "
        f"({cpu.removeprefix('cpu ')}× CPU) on the torquer day, in the timing page's newest "
        f"run ({when})"
    )
    other = next((ln for ln in section if ln.startswith("Median ratio this / that: ")), None)
    if other is not None:
        w, c = (x.strip().rstrip(".") for x in other.split(": ", 1)[1].split(","))
        text += (
            f"; {w.removeprefix('wall ')}× the wall ({c.removeprefix('cpu ')}× the CPU) of the "
            "revision that section names, in the same run"
        )
    return text


def update_readme(figure: str, readme: Path = README) -> None:
    """Rewrite the text between the README's ``diagnose_cost`` markers."""
    text = readme.read_text()
    start, end = text.index(README_BEGIN) + len(README_BEGIN), text.index(README_END)
    readme.write_text(text[:start] + figure + text[end:])


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world", type=Path, nargs="?")
    ap.add_argument("--week", type=Path, default=None)
    ap.add_argument("--build", action="store_true")
    ap.add_argument("--effect", default="temperature", help="effect of a day --build makes")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--against", type=Path, default=None, metavar="SRC")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument(
        "--readme",
        action="store_true",
        help="only rewrite the README's cost figure from the page (--out) and exit",
    )
    args = ap.parse_args()
    if args.readme:
        update_readme(readme_figure(args.out.read_text()))
        return
    if args.world is None:
        ap.error("a world directory is required (DAY_DIR), unless --readme")
    for world, days in ((args.world, 1), (args.week, 7)):
        if world is not None and args.build and not (world / "telemetry.csv").exists():
            _build(world, days, args.effect)
    if args.against is not None:
        _against(args)
        return
    base = [sys.executable, "-m", "orbitcal"]

    report = Path(tempfile.mkdtemp()) / "report.json"

    def diag(world: Path) -> list[str]:
        tel, tle = str(world / "telemetry.csv"), str(world / "spacecraft.tle")
        return [*base, "diagnose", tel, "--tle", tle, "--out", str(report)]

    tel, tle = str(args.world / "telemetry.csv"), str(args.world / "spacecraft.tle")
    lin = [*base, "calibrate", tel, "--tle", tle, "--method", "linear", "--quiet"]
    lin += ["--out", os.devnull]
    load0 = _load()
    rows = []
    for _ in range(args.repeats):
        d, c = _run(diag(args.world)), _run(lin)
        rows.append((d, c))
        print(d, c, flush=True)
    load1 = _load()
    n = Path(tel).read_text().count("\n") - 1
    wall = [d[0] / c[0] for d, c in rows]
    cpu = [d[1] / c[1] for d, c in rows]
    doc = json.loads(report.read_text())
    lines = [
        f"World `{args.world.name}`: {n:,} samples. Whole processes in turn, {args.repeats} pairs. "
        f"Load average {load0} at start, {load1} at end; nproc {os.cpu_count()}.",
        "",
        f"The diagnosis's verdict: {doc['verdict']}; held-out RMS "
        f"{doc['baseline']['holdout_rms_nt']:.3f} nT (the calibration alone) -> "
        f"{doc['final']['holdout_rms_nt']:.3f} nT (the final model).",
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
    if args.week is not None:
        load2 = _load()
        w = _run(diag(args.week))
        print(w, flush=True)
        n_week = (args.week / "telemetry.csv").read_text().count("\n") - 1
        day_wall = float(np.median([d[0] for d, _ in rows]))
        day_cpu = float(np.median([d[1] for d, _ in rows]))
        lines += [
            f"Week `{args.week.name}`: {n_week:,} samples, one diagnosis after the pairs. Load "
            f"average {load2} at start, {_load()} at end.",
            "",
            "| | wall [s] | cpu [s] | peak RSS [MB] |",
            "|---|---:|---:|---:|",
            f"| week | {w[0]:.1f} | {w[1]:.1f} | {w[2]:.0f} |",
            f"| 7 × one day (median of the pairs) | {7 * day_wall:.1f} | {7 * day_cpu:.1f} | |",
            f"| week / (7 × day) | {w[0] / (7 * day_wall):.2f} | {w[1] / (7 * day_cpu):.2f} | |",
            "",
        ]
    text = "\n".join(lines)
    args.out.write_text(text)
    print(text)


def _against(args: argparse.Namespace) -> None:
    """This revision's diagnosis against the one in ``args.against``, in turn on the same day."""
    tel, tle = str(args.world / "telemetry.csv"), str(args.world / "spacecraft.tle")
    here = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "-m", "orbitcal", "diagnose", tel, "--tle", tle, "--out", os.devnull]
    load0 = _load()
    rows = []
    for _ in range(args.repeats):
        other, this = _run(cmd, args.against.resolve()), _run(cmd, here)
        rows.append((this, other))
        print(this, other, flush=True)
    n = Path(tel).read_text().count("\n") - 1
    lines = [
        f"World `{args.world.name}`: {n:,} samples. Whole `orbitcal diagnose` processes in turn "
        f"(that revision, then this one), {args.repeats} pairs. Load average {load0} at start, "
        f"{_load()} at end; nproc {os.cpu_count()}. That revision: `{args.against}`.",
        "",
        "| pair | this wall / cpu [s] | that wall / cpu [s] | this / that wall | cpu "
        "| peak RSS this / that [MB] |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for i, (d, a) in enumerate(rows):
        lines.append(
            f"| {i + 1} | {d[0]:.1f} / {d[1]:.1f} | {a[0]:.1f} / {a[1]:.1f} | {d[0] / a[0]:.3f} "
            f"| {d[1] / a[1]:.3f} | {d[2]:.0f} / {a[2]:.0f} |"
        )
    wall = [d[0] / a[0] for d, a in rows]
    cpu = [d[1] / a[1] for d, a in rows]
    lines += [
        "",
        f"Median ratio this / that: wall {np.median(wall):.3f}, cpu {np.median(cpu):.3f}.",
    ]
    text = "\n".join(lines) + "\n"
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
