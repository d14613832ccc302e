"""Compound-world diagnosis benchmark over several plan seeds -> benchmarks/results/*.json.

    python benchmarks/diagnose_compound.py --run 1:40 2:30 3:30 11:50 12:50 \
        --tuning 1 2 3 --out /tmp/diagnose_compound.json

runs :func:`orbitcal.diagnose.bench.run_compound_benchmark` once per ``SEED:WORLDS`` (what
``orbitcal bench diagnose --compound --cases WORLDS --seed SEED`` runs) and writes one JSON with a
summary per seed, one for the tuning seeds, one for the fresh seeds, one for all, and every world
tagged with its plan seed. ``--merge FILE ...`` combines per-seed results already written (a
``{"summary", "cases", "settings"}`` document per file, e.g. from ``--compound --out``) instead.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from typing import Any

from orbitcal.diagnose.bench import run_compound_benchmark, summarise_compound


def _combine(per_seed: dict[int, dict[str, Any]], tuning: set[int]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    cases: list[dict[str, Any]] = []
    for seed, res in sorted(per_seed.items()):
        out[f"seed_{seed}"] = summarise_compound(res["cases"])
        cases += [{"bench_seed": seed, **c} for c in res["cases"]]
    tuned = [c for c in cases if c["bench_seed"] in tuning]
    fresh = [c for c in cases if c["bench_seed"] not in tuning]
    out["tuning_seeds"] = sorted(tuning & set(per_seed))
    out["tuning"] = summarise_compound(tuned) if tuned else None
    out["fresh"] = summarise_compound(fresh) if fresh else None
    out["all"] = summarise_compound(cases)
    out["settings"] = next(iter(per_seed.values()))["settings"]
    out["settings"].pop("seed", None)
    out["settings"].pop("n_cases", None)
    out["cases"] = cases
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run", nargs="*", default=[], metavar="SEED:WORLDS")
    p.add_argument("--merge", nargs="*", default=[], metavar="SEED=FILE")
    p.add_argument("--tuning", nargs="*", type=int, default=[], help="seeds used for tuning")
    p.add_argument("--out", required=True)
    args = p.parse_args()
    from orbitcal.data import real_tles_text

    per_seed: dict[int, dict[str, Any]] = {}
    t0 = time.perf_counter()
    for spec in args.run:
        seed, n = (int(x) for x in spec.split(":"))
        per_seed[seed] = run_compound_benchmark(n, seed=seed, tle_text=real_tles_text())
    for spec in args.merge:
        seed_s, path = spec.split("=", 1)
        per_seed[int(seed_s)] = json.loads(Path(path).read_text())
    out = _combine(per_seed, set(args.tuning))
    out["machine"] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "load_average_1_5_15_at_end": list(os.getloadavg()),
        "wall_seconds_of_runs": time.perf_counter() - t0 if args.run else None,
    }
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    for key in [k for k in out if k.startswith("seed_")] + ["tuning", "fresh", "all"]:
        s = out[key]
        if s:
            print(
                f"{key}: {s['worlds']} worlds, recall {s['recall']:.1%} of "
                f"{s['injected_observable']}, spurious {s['worlds_with_spurious']:.1%} "
                f"({s['spurious_per_world']:.2f}/world), verdict {s['verdict_among_injected']:.1%}"
            )


if __name__ == "__main__":
    main()
