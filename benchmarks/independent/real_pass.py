"""The real Swarm A storm pass through drawn sensors and attitudes, through ``orbitcal diagnose``.

The measured B_NEC of Swarm A (2016-01-01 00:00-00:30, storm, southern auroral crossing;
``tests/authorities/test_fac_singlesat_swarm.nc4``) is rotated into a synthetic body frame (a
tumble at a drawn rate about a random axis, or nadir pointing) and put through a drawn sensor
(0.5-3 % matrix errors, 50-500 nT offsets, 0.5-2 nT white noise). The table (ITRS quaternions,
Swarm's GPS positions) is diagnosed by the command line with its defaults and no prior.

A draw passes (issue 25, deliverable 2) when the verdict is external_field and nothing but
external_field and field_aligned_currents is significant; it is right or honest
(``ok_or_explicit``) when it passes or, with nothing else significant, the report says in words
that the ring current cannot be separated from the calibration, or cannot be told from another
effect, naming it.

``--engine rules|model|both``: each drawn table is diagnosed by each engine
(``engine_cli.py``), one row per draw and engine; the summary per engine.

    python benchmarks/independent/real_pass.py --engine both --draws 20 --seed S \
        --out RUN.json.gz
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
from common import (
    REPO,
    check_engines,
    draw_sensor,
    git_head,
    nadir_body_to_frame,
    nec_to_itrs,
    run_cli,
    spherical_to_itrs_km,
    tumbling_body_to_frame,
    write_json,
    write_table,
)

PASS_FILE = REPO / "tests" / "authorities" / "test_fac_singlesat_swarm.nc4"
EPOCH_2016_UNIX_S = 1451606400.0
ALLOWED = {"external_field", "field_aligned_currents"}
RATES_DEG_S = (0.3, 0.6, 1.0, 1.5, 2.5)


def load_pass() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    with h5py.File(PASS_FILE) as f:
        g = f["SW_OPER_MAGA_LR_1B"]
        t = EPOCH_2016_UNIX_S + g["Timestamp"][:].astype(float)
        r = spherical_to_itrs_km(g["Radius"][:] / 1000.0, g["Latitude"][:], g["Longitude"][:])
        b = nec_to_itrs(np.asarray(g["B_NEC"][:], dtype=float), r)
    return t, r, b


def judge(report: dict) -> dict:
    if "error" in report:
        return {"verdict": "error", "ok": False, "ok_or_explicit": False, "detail": report["error"]}
    sig = sorted(e["name"] for e in report["effects"] if e.get("significant"))
    gap = report.get("gap") or {}
    verdict = report["verdict"]
    honest_none = verdict == "none" and bool(gap.get("unexplained"))
    ok_verdict = verdict == "external_field"
    # "cannot be separated from the calibration on this span", naming external_field
    status = str(report.get("verdict_status") or "")
    named_absorbed = (
        ("cannot be separated from the calibration" in status or "cannot tell" in status)
        and "external_field" in status
    ) or any(
        c["name"] == "external_field" and "absorbed by the calibration" in c["refused_because"]
        for c in gap.get("closest_candidates", [])
    )
    return {
        "verdict": verdict,
        "verdict_status": report.get("verdict_status"),
        "confidence": report.get("verdict_confidence"),
        "verdict_probability": report.get("verdict_probability"),
        "probabilities": {
            e["name"]: e["probability"]
            for e in report["effects"]
            if e.get("probability") is not None
        },
        "significant": sig,
        "ok": bool(ok_verdict and set(sig) <= ALLOWED),
        # "... or an explicit 'cannot be separated from the calibration on this span' naming it"
        # (issue 25): beside a verdict of none, or of the auroral currents on their latitudes
        "ok_or_explicit": bool(
            (ok_verdict or ((honest_none or verdict in ALLOWED) and named_absorbed))
            and set(sig) <= ALLOWED
        ),
        "only_allowed_significant": set(sig) <= ALLOWED,
        "none_with_gap": honest_none,
        "baseline_holdout_rms_nt": report["baseline"]["holdout_rms_nt"],
        "final_holdout_rms_nt": (report.get("final") or {}).get("holdout_rms_nt"),
        "fell_back": (report.get("honesty") or {}).get("fell_back"),
        "gap_nt": gap.get("holdout_rms_nt"),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--seed", type=int, default=2500)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--attitudes", nargs="+", default=["tumbling", "nadir"])
    ap.add_argument("--keep", type=Path, default=None, help="keep each table and report here")
    ap.add_argument("--only", type=int, nargs="+", default=None, help="run only these draws")
    ap.add_argument("--engine", choices=("rules", "model", "both"), default="rules")
    args = ap.parse_args()
    engines = ["rules", "model"] if args.engine == "both" else [args.engine]
    chosen_by = check_engines(engines)
    t, r, b_itrs = load_pass()
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = args.keep if args.keep is not None else Path(tmp_dir)
        tmp.mkdir(parents=True, exist_ok=True)
        for attitude in args.attitudes:
            for k in range(args.draws):
                if args.only is not None and k not in args.only:
                    continue
                rng = np.random.default_rng([args.seed, k, attitude == "nadir"])
                sensor = draw_sensor(rng)
                if attitude == "tumbling":
                    rate = RATES_DEG_S[k % len(RATES_DEG_S)]
                    rot = tumbling_body_to_frame(t, rng, rate)
                else:
                    rate = 0.0
                    rot = nadir_body_to_frame(r, t, rng)
                b_body = rot.inv().apply(b_itrs)
                raw = (
                    b_body @ sensor.a.T
                    + sensor.offset_nt
                    + rng.normal(scale=sensor.noise_nt, size=b_body.shape)
                )
                table = tmp / f"pass_{attitude}_{k}.csv"
                write_table(table, t, raw, rot, r)
                for engine in engines:
                    out = table.with_name(f"{table.stem}_{engine}.json")
                    rep = run_cli(table, out, frame="ITRS", engine=engine)
                    row = {
                        "attitude": attitude,
                        "draw": k,
                        "engine": engine,
                        "rate_deg_s": rate,
                        "matrix_error_rms_pct": float(
                            np.sqrt(np.mean((sensor.a - np.eye(3)) ** 2)) * 100
                        ),
                        "offset_nt": sensor.offset_nt.round(1).tolist(),
                        "noise_nt": round(sensor.noise_nt, 3),
                        **judge(rep),
                    }
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    summary = {
        "commit": git_head(),
        "command": "python benchmarks/independent/real_pass.py "
        f"--engine {args.engine} --draws {args.draws} --seed {args.seed}",
        "engine_chosen_by": chosen_by,
        "wall_s": round(time.time() - t0, 1),
        "engines": {
            e: summarise([r for r in rows if r["engine"] == e], args.attitudes) for e in engines
        },
        "rows": rows,
    }
    write_json(args.out, summary)
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1))


def summarise(rows: list[dict], attitudes: list[str]) -> dict:
    """Pass and right-or-honest rates, overall and by attitude, and the verdicts."""

    def rate(key: str, att: str | None = None) -> float | None:
        sel = [r[key] for r in rows if att is None or r["attitude"] == att]
        return float(np.mean(sel)) if sel else None

    return {
        "draws": len(rows),
        "pass_rate": rate("ok"),
        "pass_or_explicit_rate": rate("ok_or_explicit"),
        "by_attitude": {
            a: {
                "draws": sum(r["attitude"] == a for r in rows),
                "pass_rate": rate("ok", a),
                "pass_or_explicit_rate": rate("ok_or_explicit", a),
                "verdicts": _count([r["verdict"] for r in rows if r["attitude"] == a]),
            }
            for a in attitudes
        },
    }


def _count(xs: list[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for x in xs:
        out[x] = out.get(x, 0) + 1
    return out


if __name__ == "__main__":
    main()
