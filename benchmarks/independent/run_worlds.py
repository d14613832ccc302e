"""Run independent worlds (``world.py``) through ``orbitcal diagnose`` and score the reports.

Compound worlds carry two effects drawn from the generator's list; null worlds carry none, with
the noise of one kind (white, 1/f, random walk, quantised, spikes, gaps) and, in every other
world (alternating over the kinds), small unmodelled fields (crust above degree 100, weak auroral
sheets of 3-8 nT).

Scores: recall (injected effects called significant; a second figure also credits an injected
effect that a significant one names as indistinguishable from it; a third counts only the
effects ``oracle.py`` finds observable, as the project's own benchmark does), worlds with a
spurious significant effect,
verdict among the injected, coverage of the 90 % interval of ``dt_s`` (time_offset) and the
false-alarm rate of null worlds by noise kind. Default options, no prior, the TLE the user has.

    python benchmarks/independent/run_worlds.py --compound 20 --null-per-kind 3 --seed 1000 \
        --out FILE
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from common import git_head, run_cli
from oracle import observability
from world import EFFECTS, NOISE_KINDS, make_world


def score(report: dict, injected: list[str], truth: dict) -> dict:
    if "error" in report:
        return {"error": report["error"]}
    sig = [e["name"] for e in report["effects"] if e.get("significant")]
    by_name = {e["name"]: e for e in report["effects"]}
    # Names a significant effect lists as indistinguishable from it on these data (a time-tag
    # error and an along-track orbit error under nadir pointing): credited only in the second
    # recall figure, as the project's own benchmark credits them.
    twins = {
        t for n in sig for t in (by_name[n].get("params") or {}).get("indistinguishable_from") or []
    }
    row: dict = {
        "verdict": report["verdict"],
        "verdict_status": report.get("verdict_status"),
        "significant": sig,
        "found": [e for e in injected if e in sig],
        "found_as_twin": [e for e in injected if e not in sig and e in twins],
        "spurious": [e for e in sig if e not in injected],
        "verdict_ok": report["verdict"] in injected if injected else report["verdict"] == "none",
        "baseline_holdout_rms_nt": report["baseline"]["holdout_rms_nt"],
        "final_holdout_rms_nt": (report.get("final") or {}).get("holdout_rms_nt"),
        "gap": report.get("gap"),
    }
    cover = {}
    if "dt_s" in truth and "time_offset" in sig:
        iv = (by_name["time_offset"].get("param_intervals_90") or {}).get("dt_s")
        if iv is not None:
            cover["dt_s"] = {
                "truth": truth["dt_s"],
                "interval": iv,
                "covered": bool(iv[0] <= truth["dt_s"] <= iv[1]),
                "bound_limited": bool(
                    (by_name["time_offset"].get("param_bound_limited") or {}).get("dt_s", False)
                ),
            }
    row["coverage"] = cover
    return row


def summarise(rows: list[dict]) -> dict:
    comp = [r for r in rows if r["injected"] and "error" not in r]
    null = [r for r in rows if not r["injected"] and "error" not in r]
    n_inj = sum(len(r["injected"]) for r in comp)
    covered = [c["covered"] for r in comp for c in r["coverage"].values()]
    # the project's own benchmark counts only observable effects (oracle.py)
    scored = all("oracle" in r for r in comp)
    observable = [(e, r) for r in comp for e, o in r.get("oracle", {}).items() if o["observable"]]
    by_kind = {}
    for kind in NOISE_KINDS:
        rs = [r for r in null if r["noise"] == kind]
        if rs:
            by_kind[kind] = {
                "worlds": len(rs),
                "false_alarm_rate": float(np.mean([bool(r["significant"]) for r in rs])),
                "verdict_none_rate": float(np.mean([r["verdict"] == "none" for r in rs])),
            }
    return {
        "compound_worlds": len(comp),
        "recall": sum(len(r["found"]) for r in comp) / max(n_inj, 1),
        "observable_effects": len(observable) if scored else None,
        "recall_observable": (
            sum(e in r["found"] for e, r in observable) / max(len(observable), 1)
            if scored
            else None
        ),
        "recall_with_twins": (
            sum(len(r["found"]) + len(r["found_as_twin"]) for r in comp) / max(n_inj, 1)
            if all("found_as_twin" in r for r in comp)
            else None
        ),
        "worlds_with_spurious": float(np.mean([bool(r["spurious"]) for r in comp]))
        if comp
        else None,
        "verdict_among_injected": float(np.mean([r["verdict_ok"] for r in comp])) if comp else None,
        "dt_interval_coverage_90": float(np.mean(covered)) if covered else None,
        "dt_intervals": len(covered),
        "null_worlds": len(null),
        "null_false_alarm_rate": float(np.mean([bool(r["significant"]) for r in null]))
        if null
        else None,
        "null_by_noise_kind": by_kind,
        "errors": sum("error" in r for r in rows),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--compound", type=int, default=20)
    ap.add_argument("--null-per-kind", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--keep", type=Path, default=None, help="keep each table, TLE and report here")
    ap.add_argument("--only", type=int, nargs="+", default=None, help="run these worlds only")
    args = ap.parse_args()
    plan: list[tuple[list[str], str, bool]] = []
    pick = np.random.default_rng(args.seed)
    for _ in range(args.compound):
        plan.append((sorted(pick.choice(EFFECTS, size=2, replace=False).tolist()), "white", False))
    for j, kind in enumerate(NOISE_KINDS):
        for k in range(args.null_per_kind):
            plan.append(([], kind, (j + k) % 2 == 1))  # every other world: small unmodelled fields
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        for i, (effects, noise, small) in enumerate(plan):
            if args.only is not None and i not in args.only:
                continue
            rng = np.random.default_rng([args.seed, i])
            world = make_world(rng, effects, noise=noise, small_unmodelled=small)
            oracle = observability([args.seed, i], effects, noise, small)
            stem = f"world_{i}" if args.keep else "world"
            table, tle = where / f"{stem}.csv", where / f"{stem}.tle"
            world.write(table, tle)
            rep = run_cli(table, where / f"{stem}.json", tle=tle)
            row = {
                "world": i,
                "injected": effects,
                "noise": noise,
                "small_unmodelled": small,
                "truth": world.truth,
                "oracle": oracle,
                **score(rep, effects, world.truth),
            }
            rows.append(row)
            print(
                json.dumps(
                    {
                        k: row.get(k)
                        for k in (
                            "world",
                            "injected",
                            "noise",
                            "verdict",
                            "significant",
                            "coverage",
                        )
                    }
                ),
                flush=True,
            )
    summary = {
        "commit": git_head(),
        "command": (
            f"python benchmarks/independent/run_worlds.py --compound {args.compound} "
            f"--null-per-kind {args.null_per_kind} --seed {args.seed}"
        ),
        "wall_s": round(time.time() - t0, 1),
        **summarise(rows),
        "rows": rows,
    }
    args.out.write_text(json.dumps(summary, indent=1, default=float))
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1))


if __name__ == "__main__":
    main()
