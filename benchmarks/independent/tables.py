"""Markdown tables from the JSON results of ``real_pass.py`` and ``run_worlds.py``.

    python benchmarks/independent/tables.py --real BEFORE.json AFTER.json \
        --worlds LABEL=FILE ... > benchmarks/results/diagnose_independent.md
    python benchmarks/independent/tables.py --real-summary RUN.json ...   # the README's row
    python benchmarks/independent/tables.py --real-runs LABEL=RUN.json ...  # a row per run
    python benchmarks/independent/tables.py --pooled LABEL=A.json,B.json ...  # worlds pooled
    python benchmarks/independent/tables.py --engines RUN.json.gz ... --label "tuning seeds ..." \
        --write benchmarks/results/diagnose_independent_engines.md  # engines side by side
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def _real(before: dict, after: dict) -> list[str]:
    keys_a = {(r["attitude"], r["draw"]) for r in after["rows"]}
    rows_b = [r for r in before["rows"] if (r["attitude"], r["draw"]) in keys_a]
    keys = {(r["attitude"], r["draw"]) for r in rows_b}
    after_by = {
        (r["attitude"], r["draw"]): r for r in after["rows"] if (r["attitude"], r["draw"]) in keys
    }
    rows_a = [after_by[(r["attitude"], r["draw"])] for r in rows_b]
    out = [
        "## The real Swarm A storm pass through drawn sensors and attitudes (`real_pass.py`)",
        "",
        f"Before: {before['commit']}, after: {after['commit']}; `{after['command']}`.",
        "A draw passes when the verdict is external_field and nothing but external_field and",
        "field_aligned_currents is significant. Counted over the draws that finished in both runs.",
        "",
        "| | before | after |",
        "|---|---:|---:|",
    ]

    def stat(rows: list[dict], att: str | None, key: str = "ok") -> str:
        sel = [r for r in rows if att is None or r["attitude"] == att]
        return f"{sum(bool(r.get(key)) for r in sel)} of {len(sel)}"

    for att in (None, "tumbling", "nadir"):
        label = "verdict external_field, nothing else significant" + (f", {att}" if att else "")
        out.append(f"| {label} | {stat(rows_b, att)} | {stat(rows_a, att)} |")
    for att in (None, "tumbling", "nadir"):
        label = (
            "... or an explicit 'cannot be separated from the calibration on this span' naming"
            " it (issue 25's criterion)" + (f", {att}" if att else "")
        )
        out.append(
            f"| {label} | {stat(rows_b, att, 'ok_or_explicit')} |"
            f" {stat(rows_a, att, 'ok_or_explicit')} |"
        )
    gapless = [
        sum(r["verdict"] == "none" and not r.get("none_with_gap") for r in x)
        for x in (rows_b, rows_a)
    ]
    out.append(f"| verdict none without a stated gap | {gapless[0]} | {gapless[1]} |")
    worse = [
        sum(
            (r.get("final_holdout_rms_nt") or 0) > (r.get("baseline_holdout_rms_nt") or 0) + 1e-9
            for r in x
        )
        for x in (rows_b, rows_a)
    ]
    out.append(
        f"| final model worse than the baseline on held-out data | {worse[0]} | {worse[1]} |"
    )
    extra = [sum(not r["only_allowed_significant"] for r in x) for x in (rows_b, rows_a)]
    out.append(
        f"| another effect significant besides external_field / currents |"
        f" {extra[0]} | {extra[1]} |"
    )
    out += [
        "",
        "| attitude | draw | rate [deg/s] | matrix err [%] | noise [nT] |"
        " before: verdict; significant; held-out nT |"
        " after: verdict; significant; held-out nT; gap |",
        "|---|---:|---:|---:|---:|---|---|",
    ]
    for b, a in zip(rows_b, rows_a, strict=True):
        gap = f"gap {a['gap_nt']:.1f} nT" if a.get("gap_nt") is not None else ""
        out.append(
            f"| {b['attitude']} | {b['draw']} | {b['rate_deg_s']} |"
            f" {b['matrix_error_rms_pct']:.2f} | {b['noise_nt']} |"
            f" {b['verdict']}; {', '.join(b['significant']) or '-'};"
            f" {b['baseline_holdout_rms_nt']:.1f} -> {b['final_holdout_rms_nt']:.1f} |"
            f" {a['verdict']}; {', '.join(a['significant']) or '-'};"
            f" {a['baseline_holdout_rms_nt']:.1f} -> {a['final_holdout_rms_nt']:.1f}; {gap} |"
        )
    return out


def _worlds(runs: list[tuple[str, dict]]) -> list[str]:
    out = [
        "## Independent worlds (`world.py`, `run_worlds.py`) through `orbitcal diagnose`",
        "",
        "| run | commit | compound worlds | recall | worlds with a spurious effect |"
        " verdict among injected | dt 90 % coverage (n) | null worlds | null false alarms |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, s in runs:
        cov = s.get("dt_interval_coverage_90")
        cov_s = f"{cov:.0%} ({s['dt_intervals']})" if cov is not None else "-"
        out.append(
            f"| {label} | {s['commit']} | {s['compound_worlds']} | {s['recall']:.1%} |"
            f" {s['worlds_with_spurious']:.1%} | {s['verdict_among_injected']:.1%} | {cov_s} |"
            f" {s['null_worlds']} | {s['null_false_alarm_rate']:.1%} |"
        )
    out += ["", "False alarms of the null worlds by noise kind:", ""]
    kinds = sorted({k for _, s in runs for k in s["null_by_noise_kind"]})
    out.append("| run | " + " | ".join(kinds) + " |")
    out.append("|---|" + "---:|" * len(kinds))
    for label, s in runs:
        cells = []
        for k in kinds:
            v = s["null_by_noise_kind"].get(k)
            cells.append(f"{v['false_alarm_rate']:.0%} of {v['worlds']}" if v else "-")
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def _real_summary(paths: list[Path]) -> list[str]:
    """Issue 25's criterion summed over several real_pass.py runs (the README's row)."""
    rows = [r for p in paths for r in json.loads(p.read_text())["rows"]]

    def count(att: str | None) -> str:
        sel = [r for r in rows if att is None or r["attitude"] == att]
        return f"{sum(bool(r.get('ok_or_explicit')) for r in sel)} of {len(sel)}"

    return [
        f"external field or the explicit statement, nothing else significant: {count(None)} "
        f"(nadir {count('nadir')}, tumbling {count('tumbling')}); runs: "
        + ", ".join(p.name for p in paths)
    ]


def _real_runs(runs: list[tuple[str, dict]]) -> list[str]:
    """One row per ``real_pass.py`` run: issue 25's criterion by attitude, the strict count."""
    out = [
        "| run | commit | seed | criterion, all | tumbling | nadir |"
        " verdict external_field, nothing else significant | another effect significant |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, run in runs:
        rows = run["rows"]

        def count(att: str | None, key: str = "ok_or_explicit", rows: list[dict] = rows) -> str:
            sel = [r for r in rows if att is None or r["attitude"] == att]
            return f"{sum(bool(r.get(key)) for r in sel)} of {len(sel)}"

        seed = run["command"].split("--seed")[-1].split()[0] if "--seed" in run["command"] else "-"
        extra = sum(not r["only_allowed_significant"] for r in rows)
        out.append(
            f"| {label} | {run['commit'] or '-'} | {seed} | {count(None)} | {count('tumbling')} |"
            f" {count('nadir')} | {count(None, 'ok')} | {extra} |"
        )
    return out


def _pooled(specs: list[str]) -> list[str]:
    """One row per ``LABEL=FILE,FILE,...``: recall, worlds with a spurious effect, verdict among
    the injected and null false alarms over the worlds of all the files, as ``run_worlds.py``'s
    :func:`summarise` counts them (the README's row), the recall that also credits named twins
    and how many injected effects the observability oracle finds observable (``-`` for files
    written before these were scored)."""
    from run_worlds import summarise

    out = [
        "| | recall | worlds with a spurious effect | verdict among injected | null false alarms |"
        " recall counting named twins | observable effects (oracle.py) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for spec in specs:
        label, paths = spec.split("=", 1)
        rows = [r for p in paths.split(",") for r in json.loads(Path(p).read_text())["rows"]]
        s = summarise(rows)
        n_comp, n_null = s["compound_worlds"], s["null_worlds"]
        n_inj = sum(len(r["injected"]) for r in rows if r["injected"] and "error" not in r)

        def share(rate: float | None, n: int) -> str:
            k = round((rate or 0.0) * n)
            return f"{k} of {n} = {100.0 * k / max(n, 1):.1f} %"

        out.append(
            f"| {label} | {share(s['recall'], n_inj)} | {share(s['worlds_with_spurious'], n_comp)}"
            f" | {share(s['verdict_among_injected'], n_comp)} |"
            f" {share(s['null_false_alarm_rate'], n_null)} |"
            + (
                f" {share(s['recall_with_twins'], n_inj)} |"
                if s["recall_with_twins"] is not None
                else " - |"
            )
            + (
                f" {s['observable_effects']} of {n_inj} |"
                if s["observable_effects"] is not None
                else " - |"
            )
        )
    return out


def _cell(n: int, d: int) -> str:
    return f"{n} of {d} = {100.0 * n / d:.1f} %" if d else "-"


def _oracle_commits(added: dict | None) -> list[str]:
    """The commits at which ``oracle.py`` scored a run after it (a second pass keeps the first
    as ``earlier``)."""
    return [] if added is None else [added["commit"], *_oracle_commits(added.get("earlier"))]


def _engines_worlds(runs: list[dict]) -> list[str]:
    """The independent-generator panel, one column per engine, the worlds of all ``runs``."""
    from run_worlds import summarise

    rows = [r for run in runs for r in run["rows"]]
    engines = [e for e in ("rules", "model") if any(e in run["engines"] for run in runs)]
    s = {e: summarise(rows, e) for e in engines}
    head = "| | " + " | ".join(engines) + " |"
    rule = "|---|" + "---:|" * len(engines)
    out = ["## Independent worlds (`world.py`: 1-3 effects, new shapes; null worlds by noise kind)"]
    out += ["", head, rule]

    def line(label: str, cell: object) -> None:
        out.append(f"| {label} | " + " | ".join(cell(e) for e in engines) + " |")  # type: ignore[operator]

    def share(key: str, of: str) -> object:
        return lambda e: _cell(round((s[e][key] or 0.0) * s[e][of]), s[e][of])

    line("effect worlds", lambda e: str(s[e]["compound_worlds"]))
    line("recall (injected effects named significant)", share("recall", "injected_effects"))
    line("recall counting named twins", share("recall_with_twins", "injected_effects"))
    # the observability oracle (oracle.py): only when every effect world has it
    scored = all(s[e]["observable_effects"] is not None for e in engines)
    if scored:
        after = sorted({c for run in runs for c in _oracle_commits(run.get("oracle_added"))})
        when = f", scored after the run at {', '.join(after)}" if after else ""
        line(
            f"observable injected effects (oracle.py{when})",
            lambda e: _cell(s[e]["observable_effects"], s[e]["injected_effects"]),
        )
        line(
            "recall of the observable injected effects",
            lambda e: _cell(
                sum(v["found_observable"] for v in s[e]["recall_by_effect"].values()),
                s[e]["observable_effects"],
            ),
        )
    line("worlds with a spurious effect", share("worlds_with_spurious", "compound_worlds"))
    line("verdict among the injected", share("verdict_among_injected", "compound_worlds"))
    line("null worlds with a false alarm", share("null_false_alarm_rate", "null_worlds"))
    line(
        "dt 90 % interval holds the truth",
        lambda e: _cell(
            round((s[e]["dt_interval_coverage_90"] or 0) * s[e]["dt_intervals"]),
            s[e]["dt_intervals"],
        ),
    )
    line("reports in error", lambda e: str(s[e]["errors"]))
    head_e = "| effect | " + " | ".join(engines) + (" | observable |" if scored else " |")
    out += ["", "Recall by effect:", "", head_e, rule + ("---:|" if scored else "")]
    names = sorted({n for e in engines for n in s[e]["recall_by_effect"]})
    for name in names:
        cells = []
        for e in engines:
            v = s[e]["recall_by_effect"].get(name)
            cells.append(f"{v['found']} of {v['injected']}" if v else "-")
        if scored:
            # of the injections each engine's report scored (the same unless one was in error)
            seen = [
                f"{v['observable']} of {v['injected']}"
                for e in engines
                if (v := s[e]["recall_by_effect"].get(name))
            ]
            cells.append(" / ".join(dict.fromkeys(seen)))
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    if scored:
        missed = []
        for e in engines:
            short = [
                f"{n} {v['observable'] - v['found_observable']} of {v['observable']}"
                for n, v in sorted(s[e]["recall_by_effect"].items())
                if v["found_observable"] < v["observable"]
            ]
            missed.append(f"{e}: {', '.join(short) or 'none'}")
        out += ["", "Observable injected effects not named significant: " + "; ".join(missed) + "."]
    out += ["", "False alarms of the null worlds by noise kind:", ""]
    out += ["| noise | " + " | ".join(engines) + " |", rule]
    kinds = sorted({k for e in engines for k in s[e]["null_by_noise_kind"]})
    for kind in kinds:
        cells = []
        for e in engines:
            v = s[e]["null_by_noise_kind"].get(kind)
            cells.append(
                _cell(round(v["false_alarm_rate"] * v["worlds"]), v["worlds"]) if v else "-"
            )
        out.append(f"| {kind} | " + " | ".join(cells) + " |")
    out += [
        "",
        "Reliability of the reported `probability` (effects listed, present or not). Under both"
        " engines `probability` is the model core's posterior inclusion probability (the engine"
        " chooses the verdict, not the probabilities), so the two columns are the same numbers"
        " on the same worlds:",
        "",
    ]
    for e in engines:
        rel = s[e]["reliability"]
        if not rel.get("pairs"):
            out.append(f"- {e}: the reports give no `probability`.")
            continue
        out.append(f"- {e}: {rel['pairs']} (probability, present) pairs, ECE {rel['ece']:.3f}")
        out += ["", "| bin | n | mean probability | frequency present |", "|---|---:|---:|---:|"]
        for b in rel["bins"]:
            out.append(
                f"| {b['bin'][0]:.1f}-{b['bin'][1]:.1f} | {b['n']} |"
                f" {b['mean_probability']:.3f} | {b['frequency_present']:.3f} |"
            )
        out.append("")
    return out


def _engines_cost(runs: list[dict]) -> list[str]:
    """Cost per world: making it, and each engine's diagnosis, by number of samples."""
    rows = [r for run in runs for r in run["rows"]]
    engines = [e for e in ("rules", "model") if any(e in r["engines"] for r in rows)]
    bands = ((0, 2000), (2000, 10000), (10000, 40000), (40000, 100000))
    out = ["## Cost per world (wall time on the shared 2-core machine)", ""]
    out.append(
        "| samples | worlds | make [s] median (max) | "
        + " | ".join(f"{e} diagnosis [s] median (max)" for e in engines)
        + " |"
    )
    out.append("|---|---:|---:|" + "---:|" * len(engines))
    for lo, hi in bands:
        sel = [r for r in rows if lo <= r["samples"] < hi]
        if not sel:
            continue

        def med(xs: list[float]) -> str:
            return f"{sorted(xs)[len(xs) // 2]:.0f} ({max(xs):.0f})" if xs else "-"

        cells = [
            med([r["engines"][e]["wall_s"] for r in sel if e in r["engines"]]) for e in engines
        ]
        out.append(
            f"| {lo}-{hi} | {len(sel)} | {med([r['make_s'] for r in sel])} | "
            + " | ".join(cells)
            + " |"
        )
    return out


def _engines_storm(runs: list[dict]) -> list[str]:
    """The storm-pass panel, one column per engine."""
    rows = [r for run in runs for r in run["rows"]]
    engines = [e for e in ("rules", "model") if any(r.get("engine") == e for r in rows)]
    out = ["## The Swarm A storm pass through drawn sensors (`real_pass.py`)", ""]
    out += ["| | " + " | ".join(engines) + " |", "|---|" + "---:|" * len(engines)]
    for att in (None, "tumbling", "nadir"):
        for key, label in (("ok_or_explicit", "right or honest"), ("ok", "right (strict)")):
            cells = []
            for e in engines:
                sel = [r for r in rows if r["engine"] == e and att in (None, r["attitude"])]
                cells.append(_cell(sum(bool(r[key]) for r in sel), len(sel)))
            out.append(f"| {label}{', ' + att if att else ''} | " + " | ".join(cells) + " |")
    return out


#: The figures of our simulator's panels (``benchmarks/diagnose_engines.py``), per panel.
SIM_FIGURES = {
    "blind": (
        ("top1", "top-1 verdict, all worlds (one effect or none)"),
        ("top1_strict", "top-1, strict"),
        ("min_top1_per_effect", "lowest top-1 of an effect"),
        ("false_alarm_rate", "null worlds with a false alarm"),
        ("shrink_vs_oracle_mean", "held-out shrink against the oracle's, mean"),
    ),
    "compound": (
        ("recall", "recall of the observable injected effects"),
        ("recall_all_injected", "recall of all injected effects"),
        ("worlds_with_spurious", "worlds with a spurious effect"),
        ("verdict_among_injected", "verdict among the injected"),
    ),
}


def _engines_sim(runs: list[dict]) -> list[str]:
    """Our simulator's panels, one column per engine, one table per run."""
    out: list[str] = []
    for run in runs:
        engines = [e for e in ("rules", "model") if e in run["engines"]]
        title = "240 blind worlds" if run["panel"] == "blind" else "compound worlds"
        out += [f"## Our simulator: {title} (`{run['command']}`)", ""]
        out += ["| | " + " | ".join(engines) + " |", "|---|" + "---:|" * len(engines)]
        for key, label in SIM_FIGURES[run["panel"]]:
            cells = []
            for e in engines:
                v = run["engines"][e]["summary"].get(key)
                cells.append(
                    f"{100 * v:.1f} %"
                    if isinstance(v, float) and key != "shrink_vs_oracle_mean"
                    else f"{v}"
                )
            out.append(f"| {label} | " + " | ".join(cells) + " |")
        out.append("")
    return out


def engines_page(runs: list[dict], label: str) -> str:
    """``benchmarks/results/diagnose_independent_engines.md``: every panel of ``runs``."""
    sim = [r for r in runs if "panel" in r]
    worlds = [r for r in runs if r["rows"] and "injected" in r["rows"][0]]
    storm = [r for r in runs if r["rows"] and "attitude" in r["rows"][0]]
    lines = [
        "# The diagnosis engines side by side, same worlds, one run (issue 43)",
        "",
        f"**{label}.** Generated by `benchmarks/independent/tables.py --engines`; do not edit.",
        "Runs:",
        "",
        *[f"- `{r['command']}` at {r['commit']} ({r['wall_s']:.0f} s)" for r in runs],
        "",
    ]
    if worlds:
        lines += [*_engines_worlds(worlds), "", *_engines_cost(worlds), ""]
    if storm:
        lines += [*_engines_storm(storm), ""]
    if sim:
        lines += _engines_sim(sim)
    return "\n".join(lines)


#: The README row's figures: (label in the README, the page's row label), first of each on the page.
README_FIGURES = (
    ("independent worlds: recall", "| recall (injected effects named significant) |"),
    ("spurious worlds", "| worlds with a spurious effect |"),
    ("verdict among the injected", "| verdict among the injected |"),
    ("null false alarms", "| null worlds with a false alarm |"),
    ("storm pass right or honest", "| right or honest |"),
    ("our simulator's 240 worlds top-1", "| top-1 verdict, all worlds (one effect or none) |"),
    ("compound recall", "| recall of the observable injected effects |"),
    ("compound spurious worlds", "| worlds with a spurious effect |"),
)


def readme_figures(page: str) -> str:
    """The README row's figures from an ``--engines`` page: rules / model, per panel, each the
    first table row of that label after the panel's heading (the figures are never typed)."""
    out = []
    lines = page.splitlines()
    start = 0
    for name, label in README_FIGURES:
        if name.startswith("compound"):
            start = next(
                i for i, ln in enumerate(lines) if ln.startswith("## Our simulator: compound")
            )
        elif name.startswith("our simulator"):
            start = next(i for i, ln in enumerate(lines) if ln.startswith("## Our simulator: 240"))
        line = next(ln for ln in lines[start:] if ln.startswith(label))
        cells = [c.strip() for c in line.strip("|").split("|")][1:3]
        pct = [c.rsplit("=", 1)[-1].strip().removesuffix("%").strip() for c in cells]
        out.append(f"{name} {pct[0]} / {pct[1]} %")
    return "; ".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--real-summary", nargs="+", type=Path, default=[])
    ap.add_argument("--real", nargs=2, type=Path)
    ap.add_argument("--worlds", nargs="*", default=[])
    ap.add_argument("--real-runs", nargs="*", default=[], help="LABEL=FILE, one row each")
    ap.add_argument("--pooled", nargs="*", default=[], help="LABEL=FILE,FILE: worlds pooled")
    ap.add_argument(
        "--engines", nargs="*", type=Path, default=[], help="runs, engines side by side"
    )
    ap.add_argument("--label", default="", help="what the runs are (tuning or validation seeds)")
    ap.add_argument("--write", type=Path, default=None, help="write the --engines page here")
    args = ap.parse_args()
    if args.engines:
        from common import read_json

        page = engines_page([read_json(p) for p in args.engines], args.label)
        if args.write is not None:
            args.write.write_text(page)
        else:
            print(page)
        return
    lines: list[str] = []
    if args.real_summary:
        lines += [*_real_summary(args.real_summary), ""]
    if args.real_runs:
        runs_r = []
        for spec in args.real_runs:
            label, path = spec.split("=", 1)
            runs_r.append((label, json.loads(Path(path).read_text())))
        lines += [*_real_runs(runs_r), ""]
    if args.real:
        b, a = (json.loads(p.read_text()) for p in args.real)
        lines += [*_real(b, a), ""]
    if args.pooled:
        lines += [*_pooled(args.pooled), ""]
    if args.worlds:
        runs = []
        for spec in args.worlds:
            label, path = spec.split("=", 1)
            runs.append((label, json.loads(Path(path).read_text())))
        lines += _worlds(runs)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
