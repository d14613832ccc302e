"""Summaries from the progress lines of ``real_pass.py`` / ``run_worlds.py`` (one JSON object per
finished draw or world), for runs cut short: the same scores as the scripts' own summaries, over
the draws and worlds that finished.

    python benchmarks/independent/from_logs.py real LOG --commit C > SUMMARY.json
    python benchmarks/independent/from_logs.py worlds LOG --commit C > SUMMARY.json
    python benchmarks/independent/from_logs.py worlds LOG --commit C --engine rules  # one engine
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def _rows(path: Path) -> list[dict]:
    out = []
    for line in path.read_text().splitlines():
        if line.startswith('{"attitude"') or line.startswith('{"world"'):
            out.append(json.loads(line))
    return out


def real_summary(rows: list[dict], commit: str) -> dict:
    def rate(key: str, att: str | None = None) -> float:
        sel = [r for r in rows if att is None or r["attitude"] == att]
        return float(np.mean([r.get(key, False) for r in sel])) if sel else float("nan")

    by_att = {}
    for att in ("tumbling", "nadir"):
        sel = [r for r in rows if r["attitude"] == att]
        verdicts: dict[str, int] = {}
        for r in sel:
            verdicts[r["verdict"]] = verdicts.get(r["verdict"], 0) + 1
        by_att[att] = {
            "draws": len(sel),
            "pass_rate": rate("ok", att),
            "verdicts": verdicts,
        }
    return {
        "commit": commit,
        "command": "python benchmarks/independent/real_pass.py --draws 20 --seed 2500",
        "draws_finished": len(rows),
        "pass_rate": rate("ok"),
        "by_attitude": by_att,
        "rows": rows,
    }


def worlds_summary(rows: list[dict], commit: str) -> dict:
    comp = [r for r in rows if r["injected"]]
    null = [r for r in rows if not r["injected"]]
    n_inj = sum(len(r["injected"]) for r in comp)
    found = sum(sum(e in r["significant"] for e in r["injected"]) for r in comp)
    spurious = [any(s not in r["injected"] for s in r["significant"]) for r in comp]
    covered = [c["covered"] for r in comp for c in (r.get("coverage") or {}).values()]
    by_kind: dict[str, dict] = {}
    for r in null:
        k = by_kind.setdefault(r["noise"], {"worlds": 0, "alarms": 0})
        k["worlds"] += 1
        k["alarms"] += int(bool(r["significant"]))
    for k in by_kind.values():
        k["false_alarm_rate"] = k["alarms"] / k["worlds"]
    return {
        "commit": commit,
        "compound_worlds": len(comp),
        "recall": found / max(n_inj, 1),
        "worlds_with_spurious": float(np.mean(spurious)) if comp else float("nan"),
        "verdict_among_injected": float(np.mean([r["verdict"] in r["injected"] for r in comp]))
        if comp
        else float("nan"),
        "dt_interval_coverage_90": float(np.mean(covered)) if covered else None,
        "dt_intervals": len(covered),
        "null_worlds": len(null),
        "null_false_alarm_rate": float(np.mean([bool(r["significant"]) for r in null]))
        if null
        else float("nan"),
        "null_by_noise_kind": by_kind,
        "rows": rows,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("kind", choices=["real", "worlds"])
    ap.add_argument("log", type=Path)
    ap.add_argument("--commit", required=True)
    ap.add_argument("--engine", default=None, help="the lines of this engine only")
    args = ap.parse_args()
    rows = [r for r in _rows(args.log) if args.engine in (None, r.get("engine"))]
    out = (
        real_summary(rows, args.commit)
        if args.kind == "real"
        else worlds_summary(rows, args.commit)
    )
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
