"""Which injected effects the data can show at all: an observability oracle for ``run_worlds.py``.

Shares no code with ``orbitcal``. An injected effect is *observable* when the world with only it
(every other injected effect drawn but not applied, ``make_world(..., exclude=...)``) leaves a
held-out residual of the 12-parameter calibration at least :data:`OBSERVABLE_GAIN` above the
world with none -- the definition of the project's own compound benchmark
(``orbitcal/diagnose/bench.py``), here with this generator's worlds and its own least squares.
The reference field is what a user computes: IGRF-14 at the positions of the element set they
hold, rotated into the body frame with the attitude the table gives. The calibration is fitted
on the first 70 % of the samples and judged on the last 30 % (the diagnosis's default held-out
blocks are the later 30 % of the samples).

An effect that is not observable in this sense -- a sensor temperature that settles before the
held-out blocks begin, a time-tag error under nadir pointing whose field the calibration's
matrix absorbs -- leaves no gap for any diagnosis to name, and a miss of it is counted apart.

Runs written without ``run_worlds.py --oracle`` are scored afterwards, in place::

    python benchmarks/independent/oracle.py RUN.json.gz [RUN2.json.gz ...] [--jobs 1]

Each effect world of each run (a row with effects injected and no ``oracle`` yet) gets its
``oracle``; the worlds are remade from the run's ``--seed`` and the row's world index, as
``run_worlds.py`` made them (``default_rng([seed, world])``), and a row is scored only when the
world without any effect has the row's sample count and truth (the same draws). The per-engine
summaries are recomputed (:func:`run_worlds.summarise`) and the run records when and at which
commit this was done (``oracle_added``); the engines' scores of each row are kept as they were.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from common import REPO, git_head, read_json, write_json
from world import (
    TleSet,
    World,
    gcrs_to_itrs_matrices,
    igrf14_itrs_nt,
    make_world,
    propagate_itrs_km,
)

#: Least held-out gain over the world without any injected effect [-] (the project's own
#: benchmark uses the same 3 %).
OBSERVABLE_GAIN = 0.03
#: Later fraction of the samples held out [-].
HOLDOUT_FRACTION = 0.3


def reference_body_nt(world: World, tle: TleSet) -> np.ndarray:
    """IGRF-14 at the positions of ``tle``, in the body frame of the table's attitude [nT]."""
    t = world.t_unix_s
    b_itrs = igrf14_itrs_nt(t, propagate_itrs_km(tle, t))
    b_gcrs = np.einsum("nji,nj->ni", gcrs_to_itrs_matrices(t), b_itrs)
    return world.body_to_gcrs.inv().apply(b_gcrs)


def calibration_holdout_rms_nt(b_raw_nt: np.ndarray, b_ref_nt: np.ndarray) -> float:
    """RMS per component of the held-out residual of a 12-parameter linear calibration
    (``b_raw = A b_ref + o``) fitted on the earlier samples [nT]."""
    n = b_raw_nt.shape[0]
    cut = round(n * (1.0 - HOLDOUT_FRACTION))
    x = np.column_stack([b_ref_nt, np.ones(n)])
    coef, *_ = np.linalg.lstsq(x[:cut], b_raw_nt[:cut], rcond=None)
    r = b_raw_nt[cut:] - x[cut:] @ coef
    return float(np.sqrt(np.mean(r**2)))


def observability(
    seed: list[int], effects: list[str], noise: str = "white", small_unmodelled: bool = False
) -> dict[str, dict]:
    """For each of ``effects``: the held-out RMS of the world with only it, of the world with
    none, and whether it is observable. ``seed``, ``noise`` and ``small_unmodelled`` as the
    world was made with."""
    return _observability(seed, effects, noise, small_unmodelled)[0]


def _observability(
    seed: list[int], effects: list[str], noise: str, small_unmodelled: bool
) -> tuple[dict[str, dict], World]:
    """:func:`observability` and the world without any of ``effects`` (to check that it is the
    world that was diagnosed)."""
    every = frozenset(effects)

    def world(exclude: frozenset[str]) -> tuple[World, TleSet]:
        rng = np.random.default_rng(seed)
        w = make_world(
            rng, effects, noise=noise, small_unmodelled=small_unmodelled, exclude=exclude
        )
        assert w.tle_truth is not None
        return w, w.tle_truth

    none, truth = world(every)
    floor = calibration_holdout_rms_nt(none.b_raw_nt, reference_body_nt(none, truth))
    out: dict[str, dict] = {}
    for name in effects:
        alone, truth = world(every - {name})
        # the orbit error is the user's element set; without it they would hold the truth's
        tle = alone.tle_given if name == "orbit_error" else truth
        rms = calibration_holdout_rms_nt(alone.b_raw_nt, reference_body_nt(alone, tle))
        out[name] = {
            "holdout_rms_alone_nt": round(rms, 4),
            "holdout_rms_none_nt": round(floor, 4),
            "observable": bool(rms >= floor * (1.0 + OBSERVABLE_GAIN)),
        }
    return out, none


def _same(a: object, b: object) -> bool:
    """Equal JSON values, floats to a relative 1e-12."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)
    return a == b


def _score_row(seed: int, row: dict) -> tuple[int, dict | None, str, float]:
    """(world, its ``oracle`` or None, what was checked, seconds) for one row of a run."""
    t0 = time.time()
    out, none = _observability(
        [seed, row["world"]], row["injected"], row["noise"], row["small_unmodelled"]
    )
    samples = int(none.t_unix_s.size)
    # the truth is recorded whatever is excluded: the same draws give the same truth (to the
    # last bits of a derived figure: a norm came out 1 ulp apart in one world of 20009)
    same_truth = _same(json.loads(json.dumps(none.truth, default=float)), row["truth"])
    check = f"samples {samples} (row {row['samples']}), truth {'same' if same_truth else 'DIFFERS'}"
    ok = samples == row["samples"] and same_truth
    return row["world"], (out if ok else None), check, time.time() - t0


def _shown(path: Path) -> str:
    """``path`` from the repository's root when it is inside it."""
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return str(path)


def add_to_run(path: Path, jobs: int = 1, only: list[int] | None = None) -> int:
    """Score the effect worlds of the run at ``path`` that have no ``oracle`` yet (of ``only``
    when given), recompute its per-engine summaries and write it back; returns the number of
    worlds that could not be scored (not the world that was diagnosed)."""
    from run_worlds import summarise  # not at the top: run_worlds.py --oracle imports this

    run = read_json(path)
    m = re.search(r"--seed (\d+)", run["command"])
    if m is None:
        raise SystemExit(f"{path}: no --seed in its command {run['command']!r}")
    seed = int(m.group(1))
    todo = [
        r
        for r in run["rows"]
        if r["injected"] and "oracle" not in r and (only is None or r["world"] in only)
    ]
    by_world = {r["world"]: r for r in todo}
    print(f"{path.name}: seed {seed}, {len(todo)} effect worlds to score", flush=True)
    failed = 0

    def done(world: int, oracle: dict | None, check: str, wall: float) -> None:
        nonlocal failed
        row = by_world[world]
        if oracle is None:
            failed += 1
        else:
            row["oracle"] = oracle
        seen = [e for e, o in (oracle or {}).items() if o["observable"]]
        print(
            json.dumps(
                {"run": path.name, "world": world, "injected": row["injected"],
                 "observable": seen if oracle is not None else "NOT SCORED", "check": check,
                 "wall_s": round(wall, 1)}
            ),
            flush=True,
        )  # fmt: skip

    if jobs <= 1:
        for r in todo:
            done(*_score_row(seed, r))
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_score_row, seed, r) for r in todo]
            for f in as_completed(futures):
                done(*f.result())
    if todo:
        rows = run["rows"]  # the rows scored above are these rows
        run["engines"] = {e: summarise(rows, e) for e in run["engines"]}
        added: dict = {
            # the oracle runs benchmarks/independent/ only (no orbitcal)
            "commit": git_head(("benchmarks/independent",)),
            "command": f"python benchmarks/independent/oracle.py {_shown(path)}"
            + (f" --only {' '.join(map(str, only))}" if only else ""),
            "worlds": sorted(w for w, r in by_world.items() if "oracle" in r),
        }
        if "oracle_added" in run:  # a second pass (worlds left unscored by the first)
            added["earlier"] = run["oracle_added"]
        # with the run's other keys, before the rows
        run = {k: v for k, v in run.items() if k not in ("rows", "oracle_added")}
        run |= {"oracle_added": added, "rows": rows}
        write_json(path, run)
    return failed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Add the observability oracle to run_worlds.py runs")
    ap.add_argument("runs", nargs="+", type=Path, help="RUN.json or RUN.json.gz, in place")
    ap.add_argument("--jobs", type=int, default=1, help="worlds scored at once")
    ap.add_argument("--only", type=int, nargs="+", default=None, help="these worlds only")
    args = ap.parse_args(argv)
    failed = 0
    for path in args.runs:
        failed += add_to_run(path, args.jobs, args.only)
    if failed:
        print(f"{failed} worlds not scored: not the world of their row", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
