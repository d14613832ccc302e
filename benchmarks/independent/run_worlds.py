"""Run independent worlds (``world.py``) through ``orbitcal diagnose``, each engine on the same
worlds, and score the reports.

Effect worlds carry one to three of the eleven effects (``world.draw_effects``) under noise of a
drawn kind (white, 1/f, random walk, AR(1), or a different kind and level per axis); null worlds
carry none, with the noise of each kind of ``noise.NOISE_KINDS`` in turn and, in every other
world, small unmodelled fields (crust above degree 100, weak auroral sheets of 3-8 nT). Spans of
2-24 h and cadences of 1-30 s are drawn per world.

``--engine rules|model|both``: each world is made and written once and diagnosed by each engine
(``engine_cli.py``: ``DiagnosisOptions(engine=...)``). Until ``DiagnosisOptions`` has its
``engine`` field only ``rules`` runs (the default engine), and ``model`` / ``both`` stop at once
with a message saying so.

Scores per engine (:func:`summarise`): recall (injected effects called significant; also per
effect, and crediting an effect named as indistinguishable from a significant one), worlds with
a spurious significant effect, verdict among the injected, coverage of the 90 % interval of
``dt_s``, null false alarms by noise kind, and, where the report gives a ``probability`` per
effect, the (probability, present?) pairs of a reliability diagram with their binned frequencies
and expected calibration error. Default options, no prior, the TLE the user has.

    python benchmarks/independent/run_worlds.py --engine both --seed S --out RUN.json.gz

Cost (2-core machine, one job): making a world takes 1-3 s for a few thousand samples and about
20 s for a day at 1 Hz with every effect; the diagnosis of each engine comes on top (the
``wall_s`` of each row says how long).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from common import check_engines, git_head, run_cli, write_json
from noise import COLOURED, NOISE_KINDS
from world import draw_effects, make_world

#: Noise kinds of the effect worlds: coloured, or a different kind and level per axis.
EFFECT_NOISE = (*COLOURED, "per_axis")
#: Bins of the reliability diagram.
BINS = np.linspace(0.0, 1.0, 11)


def score(report: dict, injected: list[str], truth: dict) -> dict:
    """One report against the truth of its world."""
    if "error" in report:
        return {"error": report["error"]}
    sig = [e["name"] for e in report["effects"] if e.get("significant")]
    by_name = {e["name"]: e for e in report["effects"]}
    # Names a significant effect lists as indistinguishable from it on these data: credited
    # only in the recall counting twins, as the project's own benchmark credits them.
    twins = {
        t for n in sig for t in (by_name[n].get("params") or {}).get("indistinguishable_from") or []
    }
    row: dict = {
        "verdict": report["verdict"],
        "verdict_status": report.get("verdict_status"),
        "verdict_probability": report.get("verdict_probability"),
        "significant": sig,
        "found": [e for e in injected if e in sig],
        "found_as_twin": [e for e in injected if e not in sig and e in twins],
        "spurious": [e for e in sig if e not in injected],
        "verdict_ok": report["verdict"] in injected if injected else report["verdict"] == "none",
        "probabilities": {
            e["name"]: float(e["probability"])
            for e in report["effects"]
            if e.get("probability") is not None
        },
        "baseline_holdout_rms_nt": report["baseline"]["holdout_rms_nt"],
        "final_holdout_rms_nt": (report.get("final") or {}).get("holdout_rms_nt"),
        "confirmation": report.get("confirmation"),
    }
    cover = {}
    if "dt_s" in truth and "time_offset" in sig:
        iv = (by_name["time_offset"].get("param_intervals_90") or {}).get("dt_s")
        if iv is not None:
            cover["dt_s"] = {
                "truth": truth["dt_s"],
                "interval": iv,
                "covered": bool(iv[0] <= truth["dt_s"] <= iv[1]),
            }
    row["coverage"] = cover
    return row


def _of_engine(rows: list[dict], engine: str | None) -> list[dict]:
    """Rows with the scores of ``engine`` at the top (rows of runs before engines: as they are)."""
    out = []
    for r in rows:
        if "engines" not in r:
            out.append(r)
        elif engine in r["engines"]:
            out.append({**{k: v for k, v in r.items() if k != "engines"}, **r["engines"][engine]})
    return out


def reliability(pairs: list[tuple[float, bool]]) -> dict:
    """Binned frequencies of (probability, present?) pairs and the expected calibration error."""
    if not pairs:
        return {"pairs": 0}
    p = np.array([a for a, _ in pairs], dtype=float)
    y = np.array([b for _, b in pairs], dtype=float)
    idx = np.clip(np.digitize(p, BINS[1:-1]), 0, len(BINS) - 2)
    bins, ece = [], 0.0
    for b in range(len(BINS) - 1):
        sel = idx == b
        if sel.any():
            bins.append(
                {
                    "bin": [float(BINS[b]), float(BINS[b + 1])],
                    "n": int(sel.sum()),
                    "mean_probability": float(p[sel].mean()),
                    "frequency_present": float(y[sel].mean()),
                }
            )
            ece += sel.mean() * abs(p[sel].mean() - y[sel].mean())
    return {"pairs": len(pairs), "ece": float(ece), "bins": bins}


def summarise(rows: list[dict], engine: str | None = None) -> dict:
    rows = _of_engine(rows, engine)
    comp = [r for r in rows if r["injected"] and "error" not in r]
    null = [r for r in rows if not r["injected"] and "error" not in r]
    n_inj = sum(len(r["injected"]) for r in comp)
    covered = [c["covered"] for r in comp for c in r["coverage"].values()]
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
    by_effect: dict[str, list[int]] = {}
    for r in comp:
        for e in r["injected"]:
            by_effect.setdefault(e, [0, 0, 0, 0])
            by_effect[e][0] += e in r["found"]
            by_effect[e][1] += 1
            if r.get("oracle", {}).get(e, {}).get("observable"):
                by_effect[e][2] += 1
                by_effect[e][3] += e in r["found"]
    scored = all("oracle" in r for r in comp)
    pairs = [
        (p, name in r["injected"]) for r in comp + null for name, p in r["probabilities"].items()
    ] if all("probabilities" in r for r in comp + null) else []  # fmt: skip
    return {
        "compound_worlds": len(comp),
        "injected_effects": n_inj,
        "recall": sum(len(r["found"]) for r in comp) / max(n_inj, 1),
        # with the oracle in every world: how many were observable, and found of those
        "recall_by_effect": {
            e: {"found": f, "injected": n}
            | ({"observable": o, "found_observable": fo} if scored else {})
            for e, (f, n, o, fo) in by_effect.items()
        },
        "observable_effects": len(observable) if scored else None,
        "recall_observable": (
            sum(e in r["found"] for e, r in observable) / max(len(observable), 1)
            if observable
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
        "reliability": reliability(pairs),
        "errors": sum("error" in r for r in rows),
    }


def plan(seed: int, n_effect_worlds: int, null_per_kind: int) -> list[tuple[list[str], str, bool]]:
    """(effects, noise kind, small unmodelled fields) of each world of ``seed``."""
    pick = np.random.default_rng(seed)
    out: list[tuple[list[str], str, bool]] = []
    for _ in range(n_effect_worlds):
        out.append((draw_effects(pick), str(pick.choice(EFFECT_NOISE)), False))
    for j, kind in enumerate(NOISE_KINDS):
        for k in range(null_per_kind):
            out.append(([], kind, (j + k) % 2 == 1))  # every other world: small unmodelled fields
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--compound", type=int, default=20, help="effect worlds (1-3 effects each)")
    ap.add_argument("--null-per-kind", type=int, default=2)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--engine", choices=("rules", "model", "both"), default="rules")
    ap.add_argument("--out", type=Path, required=True, help="RUN.json or RUN.json.gz")
    ap.add_argument("--oracle", action="store_true", help="also score observability (oracle.py)")
    ap.add_argument("--keep", type=Path, default=None, help="keep each table, TLE and report here")
    ap.add_argument("--only", type=int, nargs="+", default=None, help="run these worlds only")
    args = ap.parse_args()
    engines = ["rules", "model"] if args.engine == "both" else [args.engine]
    chosen_by = check_engines(engines)
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        for i, (effects, noise, small) in enumerate(
            plan(args.seed, args.compound, args.null_per_kind)
        ):
            if args.only is not None and i not in args.only:
                continue
            t_make = time.time()
            world = make_world(np.random.default_rng([args.seed, i]), effects, noise=noise,
                               small_unmodelled=small)  # fmt: skip
            stem = f"world_{i}" if args.keep else "world"
            table, tle = where / f"{stem}.csv", where / f"{stem}.tle"
            world.write(table, tle)
            row: dict = {
                "world": i,
                "injected": effects,
                "noise": noise,
                "small_unmodelled": small,
                "samples": int(world.t_unix_s.size),
                "truth": world.truth,
                "make_s": round(time.time() - t_make, 2),
                "engines": {},
            }
            if args.oracle:
                from oracle import observability

                row["oracle"] = observability([args.seed, i], effects, noise, small)
            for engine in engines:
                t_run = time.time()
                rep = run_cli(table, where / f"{stem}_{engine}.json", tle=tle, engine=engine)
                row["engines"][engine] = {
                    **score(rep, effects, world.truth),
                    "wall_s": round(time.time() - t_run, 2),
                }
                print(
                    json.dumps(
                        {"world": i, "engine": engine, "injected": effects, "noise": noise,
                         "samples": row["samples"], "make_s": row["make_s"]}
                        | {k: row["engines"][engine].get(k)
                           for k in ("verdict", "significant", "wall_s", "error")},
                        default=float,
                    ),
                    flush=True,
                )  # fmt: skip
            rows.append(row)
    summary = {
        "commit": git_head(),
        "command": (
            f"python benchmarks/independent/run_worlds.py --engine {args.engine} "
            f"--compound {args.compound} --null-per-kind {args.null_per_kind} --seed {args.seed}"
            + (" --oracle" if args.oracle else "")
            + (f" --only {' '.join(map(str, args.only))}" if args.only else "")
        ),
        "engine_chosen_by": chosen_by,
        "wall_s": round(time.time() - t0, 1),
        "engines": {e: summarise(rows, e) for e in engines},
        "rows": rows,
    }
    write_json(args.out, summary)
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1, default=float))


if __name__ == "__main__":
    main()
