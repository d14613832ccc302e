"""``orbitcal bench``: reproducible benchmarks. ``orbitcal bench diagnose --cases N --seed S``.

The blind diagnosis benchmark (:mod:`orbitcal.diagnose.bench`): worlds on real TLEs with one
effect injected and withheld, diagnosed blind; top-1 accuracy, false alarms on null worlds, shrink
against the oracle; a confusion matrix as JSON and PNG in ``--out DIR``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import platform
import time
from pathlib import Path
from typing import Any

__all__ = ["register", "run_diagnose"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``bench`` sub-command (with its ``diagnose`` benchmark)."""
    p = sub.add_parser("bench", help="run a reproducible benchmark (e.g. bench diagnose)")
    bsub = p.add_subparsers(dest="benchmark", required=True, metavar="BENCHMARK")
    d = bsub.add_parser(
        "diagnose",
        help="blind diagnosis benchmark: one withheld effect per world",
        description=(
            "Simulate worlds on real TLEs (nadir and tumbling attitude) with one effect of the "
            "catalogue injected (or none), diagnose each blind, and score top-1 accuracy, false "
            "alarms on null worlds and shrink against the oracle that knows the effect."
        ),
    )
    d.add_argument("--cases", type=int, default=240, help="number of worlds (default 240)")
    d.add_argument("--seed", type=int, default=0, help="seed of the plan and worlds (default 0)")
    d.add_argument("--out", metavar="DIR", help="write results.json, confusion.json, confusion.png")
    d.add_argument(
        "--tle",
        metavar="TLE_FILE",
        help="TLE file to draw satellites from (default: the shipped real Swarm/ISS sets)",
    )
    d.add_argument("--orbits", type=float, default=4.0, help="world length in orbits (default 4)")
    d.add_argument(
        "--compound",
        action="store_true",
        help="worlds of two and three effects at once: recall, spurious effects, verdict hits",
    )
    d.set_defaults(func=run_diagnose)


def _machine(wall_s: float) -> dict[str, object]:
    """Where and how long a benchmark ran (the ``machine`` block of its results)."""
    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": __import__("os").cpu_count(),
        "wall_seconds": wall_s,
    }


def _share(x: object, missing: str) -> str:
    """A share as a percentage, or ``missing`` when there is none (NaN: no case to count)."""
    if not isinstance(x, int | float) or not math.isfinite(float(x)):
        return missing
    return f"{float(x):.1%}"


def _ratio(x: object, missing: str = "–") -> str:
    if not isinstance(x, int | float) or not math.isfinite(float(x)):
        return missing
    return f"{float(x):.3f}"


def summary_line(s: dict[str, Any], wall_s: float) -> str:
    """The benchmark's one-line summary; a share with nothing to count is said in words (a
    draw without a null world has no false-alarm rate: "no null world", never "nan%")."""
    return (
        f"cases {s['cases']}: top-1 {_share(s['top1'], '–')} "
        f"(strict {_share(s['top1_strict'], '–')}, {s['unobservable_cases']} worlds without a "
        f"gap; min per effect {_share(s['min_top1_per_effect'], 'no effect world')}), "
        f"false alarms on null {_share(s['false_alarm_rate'], 'no null world')}, "
        f"shrink vs oracle {_ratio(s['shrink_vs_oracle_mean'], 'no effect world')} "
        f"(pooled {_ratio(s['shrink_vs_oracle_pooled'])}), {wall_s:.0f} s"
    )


def _case_line(i: int, total: int, out: dict[str, object], correct: int, wall_s: float) -> str:
    """One world's progress line: ``world 3/240: time_offset -> time_offset (right); top-1 so
    far 100.0 %, 41 s``."""
    mark = "right" if out.get("correct") else "wrong"
    return (
        f"world {i + 1}/{total}: {out.get('effect')} -> {out.get('verdict')} ({mark}); "
        f"top-1 so far {correct / (i + 1):.1%}, {wall_s:.0f} s"
    )


def run_diagnose(args: argparse.Namespace) -> int:
    """Run the blind diagnosis benchmark with a progress bar; print the summary."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from orbitcal.cli import CliError
    from orbitcal.diagnose.bench import confusion_png, run_benchmark

    if args.cases < 1:
        raise CliError("--cases must be at least 1")
    from orbitcal.data import real_tles_text

    if args.tle:
        try:
            tle_text = Path(args.tle).read_text()
        except OSError as exc:
            raise CliError(f"cannot read TLE file {args.tle}: {exc.strerror}") from None
    else:
        tle_text = real_tles_text()
    if getattr(args, "compound", False):
        return _run_compound(args, tle_text)
    console = Console(stderr=True)
    correct = 0
    t0 = time.perf_counter()
    finished: list[dict[str, object]] = []
    partial = _partial_path(args)

    def record(out: dict[str, object]) -> None:
        nonlocal correct
        finished.append(out)
        if partial is not None:  # each finished world on disk at once (Ctrl-C, a crash)
            with partial.open("a") as fh:
                fh.write(json.dumps(out) + "\n")
        correct += bool(out["correct"])

    # A bar only on a terminal: off one (a pipe, a log file, CI) it would draw nothing for the
    # whole run (9.5 min of silence at 240 worlds); one plain line per world instead.
    bar = (
        Progress(
            TextColumn("[bold]diagnose[/]"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total}"),
            TextColumn("top-1 {task.fields[acc]}"),
            TimeElapsedColumn(),
            console=console,
        )
        if console.is_terminal
        else None
    )
    with bar if bar is not None else contextlib.nullcontext():
        if bar is None:

            def on_case(i: int, out: dict[str, object]) -> None:
                record(out)
                print(_case_line(i, args.cases, out, correct, time.perf_counter() - t0), flush=True)

        else:
            progress = bar
            task = progress.add_task("cases", total=args.cases, acc="-")

            def on_case(i: int, out: dict[str, object]) -> None:
                record(out)
                progress.update(task, advance=1, acc=f"{correct / (i + 1):.1%}")

        try:
            result = run_benchmark(
                args.cases,
                seed=args.seed,
                tle_text=tle_text,
                n_orbits=args.orbits,
                progress=on_case,
            )
        except KeyboardInterrupt:  # leaving the ``with`` stops the bar
            raise _finished_note(partial, len(finished)) from None
    if partial is not None:
        partial.unlink(missing_ok=True)  # the whole results follow
    wall = time.perf_counter() - t0
    result["machine"] = _machine(wall)
    s = result["summary"]
    print(summary_line(s, wall))
    for name, entry in s["per_effect"].items():
        print(f"  {name:24s} {entry['cases']:4d} cases  top-1 {_share(entry['top1'], '–')}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "diagnose_results.json").write_text(json.dumps(result, indent=1) + "\n")
        (out / "diagnose_confusion.json").write_text(
            json.dumps(result["confusion"], indent=1) + "\n"
        )
        confusion_png(result["confusion"], out / "diagnose_confusion.png")
        print(f"results written to {out}")
    return 0


def _partial_path(args: argparse.Namespace) -> Path | None:
    """``--out/diagnose_partial.ndjson`` (emptied), where finished worlds go one line each."""
    if not args.out:
        return None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "diagnose_partial.ndjson"
    path.write_text("")
    return path


def _finished_note(partial: Path | None, n_finished: int) -> KeyboardInterrupt:
    """The interrupt to raise after Ctrl-C, saying where the finished worlds are."""
    from orbitcal.cli import Interrupted

    if partial is None:
        return Interrupted(f"{n_finished} finished worlds not saved (no --out)")
    return Interrupted(f"{n_finished} finished worlds saved to {partial} (one JSON per line)")


def _run_compound(args: argparse.Namespace, tle_text: str) -> int:
    """``bench diagnose --compound``: worlds of two and three effects (issue 14)."""
    from orbitcal.diagnose.bench import run_compound_benchmark

    t0 = time.perf_counter()

    def on_world(i: int, out: dict[str, Any]) -> None:
        # one plain line per world (the compound run had no progress at all)
        print(
            f"world {i + 1}/{args.cases}: {' + '.join(map(str, out.get('effects') or []))} -> "
            f"{', '.join(map(str, out.get('selected') or [])) or 'none'} "
            f"({len(out.get('spurious') or [])} spurious); {time.perf_counter() - t0:.0f} s",
            flush=True,
        )

    result = run_compound_benchmark(
        args.cases, seed=args.seed, tle_text=tle_text, n_orbits=args.orbits, progress=on_world
    )
    wall = time.perf_counter() - t0
    result["machine"] = _machine(wall)
    s = result["summary"]
    print(
        f"compound worlds {s['worlds']} ({s['worlds_2']} of 2, {s['worlds_3']} of 3 effects): "
        f"recall {s['recall']:.1%} of {s['injected_observable']} observable injected effects, "
        f"worlds with a spurious effect {s['worlds_with_spurious']:.1%} "
        f"({s['spurious_per_world']:.3f} per world), verdict among the injected "
        f"{s['verdict_among_injected']:.1%}, {wall:.0f} s"
    )
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "diagnose_compound_results.json").write_text(json.dumps(result, indent=1) + "\n")
        print(f"results written to {out}")
    return 0
