"""Benchmark: how long orbitcal's commands take as whole processes, and what their imports cost.

Run:  python benchmarks/startup.py [--src DIR] [--label NAME] [--runs N] [--out PATH]

Whole processes, timed from outside (``subprocess`` start to exit, wall clock), each ``--runs``
times after one warm-up run, median quoted (min and max beside it):

- ``python -c "import orbitcal"``, ``orbitcal --help`` and ``orbitcal X --help`` for every command;
- ``orbitcal truth`` on 86,400 samples (one day at 1 s of a tumbling Swarm A on its real TLE, from
  ``orbitcal simulate``) beside its peer ``benchmarks/truth_peer.py`` (Skyfield + chaosmagpy, the
  same job and output), the two alternating run by run so the ratio is taken pair by pair.

Import-time breakdown: ``python -X importtime`` of ``orbitcal --help`` and of ``orbitcal truth``,
the biggest top-level imports by cumulative time.

``--src DIR`` runs the orbitcal package found in DIR (``PYTHONPATH=DIR``, e.g. ``git archive`` of
an older commit; every process runs in ``benchmarks/_work/startup`` so that the repository's own
``orbitcal/`` is not first on ``sys.path``) instead of the installed one, to measure "before" and
"after" in one session. The
figures of each label go to ``benchmarks/results/startup.json``; ``benchmarks/results/startup.md``
is regenerated from all labels there, with the machine and its load.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WORK = REPO / "benchmarks" / "_work" / "startup"
RESULTS_JSON = REPO / "benchmarks" / "results" / "startup.json"
COMMANDS = ("truth", "simulate", "calibrate", "apply", "reproduce", "diagnose", "bench", "data")
SERVICE_COMMANDS = ("serve", "worker", "demo")
N_SAMPLES = 86_400


def _env(src: str | None) -> dict[str, str]:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _orbitcal(*args: str) -> list[str]:
    return [sys.executable, "-m", "orbitcal", *args]


#: CPU seconds (user + system) of the last finished child, beside its wall time: on a loaded
#: machine the wall clock includes waiting for a core, the CPU time does not.
_LAST_CPU_S = [0.0]


def _time(cmd: list[str], env: dict[str, str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        cmd, env=env, cwd=WORK, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    _LAST_CPU_S[0] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall


def _stats(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def _measure(cmd: list[str], env: dict[str, str], runs: int) -> dict[str, float]:
    _time(cmd, env)  # warm-up: file cache, numba's on-disk cache
    walls, cpus = [], []
    for _ in range(runs):
        walls.append(_time(cmd, env))
        cpus.append(_LAST_CPU_S[0])
    return {**_stats(walls), "cpu_median": statistics.median(cpus)}


def _world(env: dict[str, str]) -> Path:
    out = WORK / "world86400"
    if not (out / "telemetry.csv").exists():
        subprocess.run(
            _orbitcal(
                "simulate",
                "--tle",
                str(REPO / "tests" / "authorities" / "swarm_iss_real_tles.tle"),
                "--norad",
                "39452",
                "--start",
                "2022-08-02T00:00:00Z",
                "--duration-s",
                str(N_SAMPLES),
                "--cadence-s",
                "1",
                "--attitude",
                "tumbling",
                "--seed",
                "1",
                "--out",
                str(out),
            ),
            env=env,
            cwd=WORK,
            check=True,
        )
    return out


def _importtime(args: list[str], env: dict[str, str], top: int = 12) -> list[tuple[str, float]]:
    """The ``top`` biggest imports (cumulative seconds) of a run, at any depth below __main__."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "orbitcal", *args],
        env=env,
        cwd=WORK,
        capture_output=True,
        text=True,
        check=False,
    )
    rows: list[tuple[int, str]] = []
    total = 0
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \|( +)(\S+)", line)
        if m and len(m[2]) == 1:  # an import made by __main__ itself
            total += int(m[1])
        if m and len(m[2]) <= 3:  # top-level imports and what they import directly
            rows.append((int(m[1]), m[3]))
    rows.sort(reverse=True)
    out = [(name, us / 1e6) for us, name in rows[:top]]
    return [("(all imports)", total / 1e6), *out]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", help="run orbitcal from this directory (PYTHONPATH)")
    parser.add_argument("--label", default="after", help="name of this measurement")
    parser.add_argument("--runs", type=int, default=5, help="runs per command (median quoted)")
    parser.add_argument("--truth-runs", type=int, default=5, help="paired truth/peer runs")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "startup.md")
    args = parser.parse_args()
    env = _env(args.src)
    WORK.mkdir(parents=True, exist_ok=True)  # also the working directory: '' on sys.path
    where = subprocess.run(
        [sys.executable, "-c", "import orbitcal; print(orbitcal.__file__)"],
        env=env,
        cwd=WORK,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    print(f"measuring {where}", file=sys.stderr)
    load_start = os.getloadavg()
    result: dict[str, object] = {"date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M")}

    help_times: dict[str, dict[str, float]] = {}
    help_times["import orbitcal"] = _measure(
        [sys.executable, "-c", "import orbitcal"], env, args.runs
    )
    help_times["orbitcal --help"] = _measure(_orbitcal("--help"), env, args.runs)
    for name in (*COMMANDS, *SERVICE_COMMANDS):
        help_times[f"orbitcal {name} --help"] = _measure(_orbitcal(name, "--help"), env, args.runs)
    result["help"] = help_times

    world = _world(env)
    tel, tle = str(world / "telemetry.csv"), str(world / "spacecraft.tle")
    truth_cmd = _orbitcal("truth", tel, "--tle", tle, "--out", str(WORK / "truth.csv"))
    peer_cmd = [
        sys.executable,
        str(REPO / "benchmarks" / "truth_peer.py"),
        tel,
        tle,
        str(WORK / "peer.csv"),
    ]
    _time(truth_cmd, env)
    _time(peer_cmd, env)
    ours, peer, ratio, cpu_ratio = [], [], [], []
    for _ in range(args.truth_runs):
        a = _time(truth_cmd, env)
        a_cpu = _LAST_CPU_S[0]
        b = _time(peer_cmd, env)
        ours.append(a)
        peer.append(b)
        ratio.append(b / a)
        cpu_ratio.append(_LAST_CPU_S[0] / a_cpu)
    result["truth"] = {
        "orbitcal": _stats(ours),
        "peer": _stats(peer),
        "ratio": _stats(ratio),
        "cpu_ratio": _stats(cpu_ratio),
    }
    result["importtime"] = {
        "orbitcal --help": _importtime(["--help"], env),
        "orbitcal truth": _importtime(
            ["truth", tel, "--tle", tle, "--out", str(WORK / "truth.csv")], env
        ),
    }
    result["load"] = [list(load_start), list(os.getloadavg())]

    all_results = json.loads(RESULTS_JSON.read_text()) if RESULTS_JSON.exists() else {}
    all_results[args.label] = result
    RESULTS_JSON.write_text(json.dumps(all_results, indent=1) + "\n")
    args.out.write_text(_markdown(all_results))
    print(args.out.read_text())


def _fmt(s: dict[str, float]) -> str:
    cpu = f"; cpu {s['cpu_median']:.2f} s" if "cpu_median" in s else ""
    return f"{s['median']:.2f} s ({s['min']:.2f}–{s['max']:.2f}{cpu})"


def _markdown(results: dict[str, dict[str, object]]) -> str:
    labels = list(results)
    lines = [
        "# Start-up benchmark (`benchmarks/startup.py`)",
        "",
        "Whole processes timed from outside (start to exit, wall clock): median of the runs, "
        "(min–max) beside it. `orbitcal truth` runs on 86,400 samples (one day at 1 s, tumbling "
        "Swarm A on its real TLE) alternately with its peer `benchmarks/truth_peer.py` (Skyfield "
        "SGP4 and frames + chaosmagpy IGRF-14, pandas in and out; agrees with orbitcal to "
        "0.16 nT); the ratio is peer / orbitcal, taken pair by pair. Wall times include waiting "
        "for a core on this shared machine (look at the load average); the CPU time (user + "
        "system of the process, median) beside them does not. Compare wall times across labels "
        "only at a similar load; the pair-by-pair ratio and the CPU times hold under load.",
        "",
        "## Machine",
        "",
        f"- {platform.machine()}, {os.cpu_count()} cores, shared with other developers; "
        f"Python {platform.python_version()}",
    ]
    for label in labels:
        r = results[label]
        load = r["load"]  # type: ignore[index]
        lines.append(
            f"- `{label}` measured {r['date']} UTC; 1-min load average {load[0][0]:.1f} at start, "  # type: ignore[index]
            f"{load[1][0]:.1f} at end"  # type: ignore[index]
        )
    lines += ["", "## Commands (whole process)", ""]
    lines.append("| command | " + " | ".join(labels) + " |")
    lines.append("|---|" + "---:|" * len(labels))
    keys: list[str] = []
    for label in labels:
        for key in results[label]["help"]:  # type: ignore[attr-defined]
            if key not in keys:
                keys.append(key)
    for key in keys:
        cells = []
        for label in labels:
            h = results[label]["help"]  # type: ignore[index]
            cells.append(_fmt(h[key]) if key in h else "–")  # type: ignore[operator,index]
        lines.append(f"| `{key}` | " + " | ".join(cells) + " |")
    for what in ("orbitcal", "peer"):
        name = (
            "`orbitcal truth` (86,400 samples)"
            if what == "orbitcal"
            else "peer (Skyfield + chaosmagpy)"
        )
        lines.append(
            f"| {name} | "
            + " | ".join(_fmt(results[lb]["truth"][what]) for lb in labels)  # type: ignore[index]
            + " |"
        )
    lines.append(
        "| **peer / orbitcal truth** | "
        + " | ".join(
            f"**{results[lb]['truth']['ratio']['median']:.2f}×** "  # type: ignore[index]
            f"({results[lb]['truth']['ratio']['min']:.2f}–{results[lb]['truth']['ratio']['max']:.2f})"  # type: ignore[index]
            for lb in labels
        )
        + " |"
    )
    lines.append(
        "| peer / orbitcal truth, CPU time | "
        + " | ".join(
            f"{results[lb]['truth']['cpu_ratio']['median']:.2f}×"  # type: ignore[index]
            if "cpu_ratio" in results[lb]["truth"]  # type: ignore[operator]
            else "–"
            for lb in labels
        )
        + " |"
    )
    lines += ["", "## Import time (`python -X importtime`, cumulative, top-level imports)", ""]
    for label in labels:
        for run, rows in results[label]["importtime"].items():  # type: ignore[attr-defined]
            lines.append(f"**{label}**, `{run}`: " + ", ".join(f"{n} {s:.2f} s" for n, s in rows))
            lines.append("")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
