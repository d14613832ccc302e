"""The blind benchmark: worlds with one injected effect, diagnosed without being told which.

Each case is a world of :func:`orbitcal.simulate.simulate_world` on a real TLE (Swarm A/B/C or the
ISS, ``orbitcal/data/swarm_iss_real_tles.tle`` shipped with the package, or
any TLE file given), with nadir or tumbling attitude, one effect of the CONTRACT section-5
catalogue at one of several magnitudes (or none: the null world), a random sensor and noise. The
diagnosis sees only the telemetry and the TLE (:func:`orbitcal.diagnose.api.diagnosis_data`), never
the truth.

Scores:

* top-1 accuracy: the verdict equals the injected effect (``"none"`` for null worlds). An effect
  that leaves no held-out gap even for the perfect oracle below (its shrink < 1 + the
  diagnosis' own 3 % naming threshold: absorbed whole by the 12 parameters) may also be answered
  ``"none"``; ``top1_strict`` counts only the injected name, and ``unobservable_cases`` how many
  such worlds the run had;
* false alarms: null worlds where an effect is named;
* shrink vs oracle: the diagnosis' held-out shrink (baseline / with the selected effects) over the
  shrink of an oracle that knows which effect was injected and fits the catalogue's model of it
  the same way; and, for information, over the shrink of a perfect oracle that subtracts the
  injected field itself before calibrating.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from orbitcal.diagnose.attribution import attribute, fit_joint
from orbitcal.diagnose.effects import EFFECT_NAMES, get_effect
from orbitcal.diagnose.honesty import reviewed
from orbitcal.metrics import norm_rms_nt

__all__ = [
    "BENCH_CLASSES",
    "MAGNITUDES",
    "BenchCase",
    "confusion_matrix",
    "plan_cases",
    "run_benchmark",
    "run_case",
    "summarise",
]

#: Perfect-oracle shrink below 1 + this: the injected effect leaves no gap to diagnose (the
#: diagnosis' own ``min_gain``).
OBSERVABLE_GAIN = 0.03

#: Classes of the benchmark: the null world and every catalogue effect.
BENCH_CLASSES: tuple[str, ...] = ("none", *EFFECT_NAMES)

#: Magnitudes relative to each effect's default (``orbitcal.simulate.effects``).
MAGNITUDES: tuple[float, ...] = (0.5, 1.0, 2.0)

#: Per-effect magnitude sets where the default sits at the physical detection limit: the real
#: crust (MF7 at scale 1, ~3 nT rms) is not scaled below itself, and along-track errors start at
#: the simulator's 1 km (below it, a constant along-track error is absorbed under nadir pointing
#: and is indistinguishable from a time-tag error under a steady spin but for Earth rotation).
MAGNITUDES_BY_EFFECT: dict[str, tuple[float, ...]] = {
    "crustal_field": (1.0, 1.5, 2.0),
    "orbit_error": (1.0, 2.0, 4.0),
}

#: Field-aligned currents only flow at |magnetic latitude| > ~60 deg: their worlds use the polar
#: Swarm orbits (the ISS at 51.6 deg barely reaches the auroral oval).
POLAR_NORAD_IDS: tuple[int, ...] = (39452, 39451, 39453)

ATTITUDES: tuple[str, ...] = ("nadir", "tumbling")

#: Satellites drawn for the worlds (NORAD ids in the shipped TLE file).
NORAD_IDS: tuple[int, ...] = (39452, 39451, 39453, 25544)


@dataclass(frozen=True)
class BenchCase:
    """One benchmark world."""

    index: int
    effect: str
    magnitude: float
    attitude: str
    norad_id: int
    seed: int


def plan_cases(n_cases: int, *, seed: int) -> list[BenchCase]:
    """Balanced plan: cycle over classes x attitudes x magnitudes, satellites and seeds random."""
    rng = np.random.default_rng(seed)
    grid = [(e, a, k) for k in range(len(MAGNITUDES)) for a in ATTITUDES for e in BENCH_CLASSES]
    order = rng.permutation(len(grid))
    cases = []
    for i in range(n_cases):
        e, a, k = grid[order[i % len(grid)]]
        m = 0.0 if e == "none" else MAGNITUDES_BY_EFFECT.get(e, MAGNITUDES)[k]
        ids = POLAR_NORAD_IDS if e == "field_aligned_currents" else NORAD_IDS
        cases.append(
            BenchCase(
                index=i,
                effect=e,
                magnitude=m,
                attitude=a,
                norad_id=int(rng.choice(ids)),
                seed=int(rng.integers(0, 2**31 - 1)),
            )
        )
    return cases


def _scaled_effect(name: str, magnitude: float, rng: np.random.Generator) -> Any:
    """The simulator's effect at ``magnitude`` times its default size."""
    from orbitcal.simulate.effects import EFFECTS, make_effect

    default: Any = EFFECTS[name]()
    m = float(magnitude)
    params: dict[str, Any] = {}
    if name == "temperature":
        params = {
            "bias_nt_per_c": np.array(default.bias_nt_per_c) * m,
            "scale_per_c": np.array(default.scale_per_c) * m,
        }
    elif name == "magnetorquer":
        params = {"coupling_nt_per_am2": np.array(default.coupling_nt_per_am2) * m}
    elif name == "time_offset":
        params = {"offset_s": default.offset_s * m * float(rng.choice([-1.0, 1.0]))}
    elif name == "external_field":
        if rng.random() < 0.5:
            params = {"model": "RC", "scale": m}
        else:
            params = {"amplitude_nt": default.amplitude_nt * m, "recovery_time_s": 2.0e4}
    elif name == "crustal_field":
        params = {"model": "MF7", "scale": m}
    elif name == "sun_driven":
        params = {"pattern_nt": np.array(default.pattern_nt) * m}
    elif name == "nonlinearity":
        params = {"cubic_per_nt2": np.array(default.cubic_per_nt2) * m}
    elif name == "orbit_error":
        params = {"along_track_km": default.along_track_km * m * float(rng.choice([-1.0, 1.0]))}
    elif name == "parameter_drift":
        params = {
            "step_nt": np.array(default.step_nt) * m,
            "trend_nt_per_day": np.array(default.trend_nt_per_day) * m,
            "step_at_fraction": float(rng.uniform(0.25, 0.6)),
        }
    elif name == "field_aligned_currents":
        params = {"amplitude_nt": default.amplitude_nt * m}
    elif name == "attitude_error":
        params = {"amplitude_deg": default.amplitude_deg * m}
    return make_effect(name, **params)


def _case_orbit(
    norad_id: int, attitude_name: str, tle_text: str, rng: np.random.Generator
) -> tuple[Any, float, Any]:
    """A case's element set, start time and attitude, drawn from ``rng`` in this order: one of
    the sets of ``norad_id``, a start within a day of its epoch, then (tumbling) a rate of
    0.5-3 deg/s and an initial attitude. Shared by the single-effect and compound cases."""
    from orbitcal.simulate import NadirLVLH, Tumbling, select_tle

    tles = [s for s in _tle_sets(tle_text) if s.norad_id == norad_id]
    tle = tles[int(rng.integers(len(tles)))]
    start = tle.epoch_utc_s + float(rng.uniform(0.0, 86400.0))
    tle = select_tle(tle_text, norad_id=norad_id, at_utc_s=start)
    if attitude_name == "nadir":
        attitude: Any = NadirLVLH()
    else:
        rate = rng.normal(size=3)
        rate *= float(rng.uniform(0.5, 3.0)) / np.linalg.norm(rate)
        q0 = rng.normal(size=4)
        attitude = Tumbling(
            rate_body_deg_s=tuple(float(x) for x in rate),  # type: ignore[arg-type]
            q0_wxyz=tuple(float(x) for x in q0 / np.linalg.norm(q0)),  # type: ignore[arg-type]
        )
    return tle, start, attitude


def _world_and_data(
    tle: Any,
    start: float,
    attitude: Any,
    effects: list[Any],
    rng: np.random.Generator,
    *,
    n_orbits: float,
    cadence_s: float,
    crust_model: str | None,
) -> tuple[Any, Any]:
    """Simulate ``n_orbits`` orbits from ``start``; ``(world, data)`` as the diagnosis sees it."""
    from orbitcal.diagnose.api import diagnosis_data
    from orbitcal.orbit import Orbit
    from orbitcal.simulate import simulate_world

    period_s = 86400.0 / float(tle.line2[52:63])
    world = simulate_world(
        tle,
        start_utc_s=start,
        duration_s=n_orbits * period_s,
        cadence_s=cadence_s,
        rng=rng,
        attitude=attitude,
        effects=effects,
    )
    data = diagnosis_data(world.telemetry, orbit=Orbit.from_tle(tle.text), crust_model=crust_model)
    return world, data


def run_case(
    case: BenchCase,
    *,
    tle_text: str,
    n_orbits: float = 4.0,
    cadence_s: float = 10.0,
    crust_model: str | None = "LCS-1",
) -> dict[str, Any]:
    """Simulate one world, diagnose it blind, score it against the truth and the oracles."""
    rng = np.random.default_rng(case.seed)
    tle, start, attitude = _case_orbit(case.norad_id, case.attitude, tle_text, rng)
    effects = [] if case.effect == "none" else [_scaled_effect(case.effect, case.magnitude, rng)]
    t0 = time.perf_counter()
    world, data = _world_and_data(
        tle,
        start,
        attitude,
        effects,
        rng,
        n_orbits=n_orbits,
        cadence_s=cadence_s,
        crust_model=crust_model,
    )
    att = reviewed(data, attribute(data, split_tests=False))  # issue 25: honesty.review
    elapsed = time.perf_counter() - t0

    # Oracle 1: knows the effect, fits its catalogue model the same way.
    oracle_rms = att.baseline_rms_nt
    if case.effect != "none":
        block = get_effect(case.effect).design(data, att.train)
        if block is not None:
            from orbitcal.diagnose.attribution import _resolve

            chosen = _resolve(data, att.train, [], block)
            fit = fit_joint(data, att.train, [chosen])
            r = data.b_raw_nt - fit.predict_nt(data)
            oracle_rms = norm_rms_nt(r[att.holdout])
    # Oracle 2: subtracts the injected field (in sensor axes) and calibrates.
    injected = sum(world.injected_body_nt.values(), np.zeros_like(data.b_raw_nt))
    from orbitcal.diagnose.effects import DiagnosisData

    clean = DiagnosisData(
        t_utc_s=data.t_utc_s,
        b_raw_nt=data.b_raw_nt - injected @ np.asarray(world.sensor.a_matrix).T,
        b_ref_body_nt=data.b_ref_body_nt,
        rot_itrs_to_body=data.rot_itrs_to_body,
        r_itrs_km=data.r_itrs_km,
    )
    fit_clean = fit_joint(clean, att.train, [])
    perfect_rms = norm_rms_nt((clean.b_raw_nt - fit_clean.predict_nt(clean))[att.holdout])

    base = att.baseline_rms_nt
    shrink = base / max(att.final_rms_nt, 1e-12)
    oracle_shrink = base / max(oracle_rms, 1e-12)
    perfect_shrink = base / max(perfect_rms, 1e-12)
    injected_rms = float(world.truth["effects"][0]["rms_nt"]) if effects else 0.0
    # An effect that leaves no held-out gap even for the perfect oracle (absorbed whole by the 12
    # parameters, e.g. a thermal bias in continuous sunlight) cannot be named from the residual:
    # there "none" is a true statement about the gap and counts as correct, as the injected name
    # (found by a split fit) does.
    observable = case.effect == "none" or perfect_shrink >= 1.0 + OBSERVABLE_GAIN
    strict = att.verdict == case.effect
    return {
        "index": case.index,
        "effect": case.effect,
        "magnitude": case.magnitude,
        "attitude": case.attitude,
        "norad_id": case.norad_id,
        "seed": case.seed,
        "verdict": att.verdict,
        "selected": list(att.selected),
        "correct": strict or (not observable and att.verdict == "none"),
        "correct_strict": strict,
        "observable": observable,
        "injected_rms_nt": injected_rms,
        "baseline_holdout_rms_nt": base,
        "final_holdout_rms_nt": att.final_rms_nt,
        "shrink": shrink,
        "oracle_holdout_rms_nt": oracle_rms,
        "oracle_shrink": oracle_shrink,
        "perfect_holdout_rms_nt": perfect_rms,
        "perfect_shrink": perfect_shrink,
        "shrink_vs_oracle": shrink / max(oracle_shrink, 1e-12),
        "shrink_vs_perfect": shrink / max(perfect_shrink, 1e-12),
        "seconds": elapsed,
    }


def _tle_sets(text: str) -> list[Any]:
    from orbitcal.simulate import parse_tles

    return list(parse_tles(text))


def confusion_matrix(results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Counts of verdicts per injected class (rows: truth, columns: verdict)."""
    labels = list(BENCH_CLASSES)
    m = np.zeros((len(labels), len(labels)), dtype=int)
    for r in results:
        m[labels.index(r["effect"]), labels.index(r["verdict"])] += 1
    return {"labels": labels, "rows": "injected", "columns": "verdict", "counts": m.tolist()}


def summarise(results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Overall and per-effect scores."""
    res = list(results)
    per: dict[str, Any] = {}
    for label in BENCH_CLASSES:
        rows = [r for r in res if r["effect"] == label]
        if not rows:
            continue
        entry: dict[str, Any] = {
            "cases": len(rows),
            "top1": float(np.mean([r["correct"] for r in rows])),
        }
        if label != "none":
            ok = [r for r in rows if r["correct"]]
            entry["median_shrink"] = float(np.median([r["shrink"] for r in rows]))
            entry["median_oracle_shrink"] = float(np.median([r["oracle_shrink"] for r in rows]))
            entry["mean_shrink_vs_oracle"] = float(np.mean([r["shrink_vs_oracle"] for r in rows]))
            entry["mean_shrink_vs_oracle_when_correct"] = (
                float(np.mean([r["shrink_vs_oracle"] for r in ok])) if ok else None
            )
            entry["mean_shrink_vs_perfect"] = float(np.mean([r["shrink_vs_perfect"] for r in rows]))
            by_mag = {}
            for mag in sorted({r["magnitude"] for r in rows}):
                sub = [r for r in rows if r["magnitude"] == mag]
                by_mag[f"{mag:g}"] = float(np.mean([r["correct"] for r in sub]))
            entry["top1_by_magnitude"] = by_mag
        per[label] = entry
    effect_rows = [r for r in res if r["effect"] != "none"]
    null_rows = [r for r in res if r["effect"] == "none"]
    total_shrink = sum(r["shrink"] for r in effect_rows)
    total_oracle = sum(r["oracle_shrink"] for r in effect_rows)
    return {
        "cases": len(res),
        "top1": float(np.mean([r["correct"] for r in res])) if res else float("nan"),
        "top1_strict": (
            float(np.mean([r.get("correct_strict", r["correct"]) for r in res]))
            if res
            else float("nan")
        ),
        "unobservable_cases": sum(1 for r in res if not r.get("observable", True)),
        "min_top1_per_effect": min(
            (v["top1"] for k, v in per.items() if k != "none"), default=float("nan")
        ),
        "null_cases": len(null_rows),
        "false_alarm_rate": float(np.mean([not r["correct"] for r in null_rows]))
        if null_rows
        else float("nan"),
        "shrink_vs_oracle_mean": float(np.mean([r["shrink_vs_oracle"] for r in effect_rows]))
        if effect_rows
        else float("nan"),
        "shrink_vs_oracle_pooled": total_shrink / total_oracle if total_oracle else float("nan"),
        "shrink_vs_perfect_mean": float(np.mean([r["shrink_vs_perfect"] for r in effect_rows]))
        if effect_rows
        else float("nan"),
        "seconds_total": float(sum(r["seconds"] for r in res)),
        "per_effect": per,
    }


def confusion_png(matrix: dict[str, Any], path: str | Path) -> None:
    """Write the confusion matrix as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    counts = np.array(matrix["counts"])
    labels = matrix["labels"]
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.imshow(counts, cmap="Blues")
    ax.set_xticks(range(len(labels)), labels, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    for i in range(len(labels)):
        for j in range(len(labels)):
            if counts[i, j]:
                color = "white" if counts[i, j] > counts.max() / 2 else "black"
                ax.text(j, i, str(counts[i, j]), ha="center", va="center", fontsize=8, color=color)
    ax.set_xlabel("verdict")
    ax.set_ylabel("injected")
    ax.set_title("Blind diagnosis benchmark: confusion matrix")
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)


def run_benchmark(
    n_cases: int,
    *,
    seed: int,
    tle_text: str,
    n_orbits: float = 4.0,
    cadence_s: float = 10.0,
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Run ``n_cases`` blind cases; returns ``{"summary", "confusion", "cases"}``.

    BLAS is limited to one thread for the run (tiny fits on a shared machine).
    """
    from orbitcal.blas import one_blas_thread

    results = []
    with one_blas_thread():
        for case in plan_cases(n_cases, seed=seed):
            out = run_case(case, tle_text=tle_text, n_orbits=n_orbits, cadence_s=cadence_s)
            results.append(out)
            if progress is not None:
                progress(case.index, out)
    return {
        "summary": summarise(results),
        "confusion": confusion_matrix(results),
        "cases": results,
        "settings": {
            "n_cases": n_cases,
            "seed": seed,
            "n_orbits": n_orbits,
            "cadence_s": cadence_s,
            "magnitudes": list(MAGNITUDES),
            "magnitudes_by_effect": {k: list(v) for k, v in MAGNITUDES_BY_EFFECT.items()},
            "polar_only": ["field_aligned_currents"],
            "attitudes": list(ATTITUDES),
            "norad_ids": list(NORAD_IDS),
        },
    }


# ---- compound worlds ---------------------------------------------------------------------------

#: Magnitudes of the compound worlds (relative to each effect's default; per-effect sets as above).
COMPOUND_MAGNITUDE_INDEX: tuple[int, ...] = (1, 2)


@dataclass(frozen=True)
class CompoundCase:
    """One world with several effects injected at once."""

    index: int
    effects: tuple[str, ...]
    magnitudes: tuple[float, ...]
    attitude: str
    norad_id: int
    seed: int


def plan_compound_cases(n_cases: int, *, seed: int) -> list[CompoundCase]:
    """Worlds of two and three distinct effects (alternately), drawn at random from the catalogue.

    Magnitudes are the simulator's default or twice it (per-effect sets of
    ``MAGNITUDES_BY_EFFECT``); a world with field-aligned currents flies a polar Swarm orbit.
    """
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n_cases):
        k = 2 + i % 2
        names = tuple(str(x) for x in rng.choice(EFFECT_NAMES, size=k, replace=False))
        mags = tuple(
            float(
                MAGNITUDES_BY_EFFECT.get(n, MAGNITUDES)[int(rng.choice(COMPOUND_MAGNITUDE_INDEX))]
            )
            for n in names
        )
        ids = POLAR_NORAD_IDS if "field_aligned_currents" in names else NORAD_IDS
        cases.append(
            CompoundCase(
                index=i,
                effects=names,
                magnitudes=mags,
                attitude=ATTITUDES[int(rng.integers(len(ATTITUDES)))],
                norad_id=int(rng.choice(ids)),
                seed=int(rng.integers(0, 2**31 - 1)),
            )
        )
    return cases


def simulate_compound_world(
    case: CompoundCase,
    *,
    tle_text: str,
    n_orbits: float = 4.0,
    cadence_s: float = 10.0,
    crust_model: str | None = "LCS-1",
) -> tuple[Any, Any]:
    """The world of a compound case and the diagnosis data built from its telemetry and TLE.

    Returns ``(world, data)``: the :func:`orbitcal.simulate.simulate_world` result (with the
    truth) and the :class:`orbitcal.diagnose.effects.DiagnosisData` the diagnosis sees.
    """
    rng = np.random.default_rng(case.seed)
    tle, start, attitude = _case_orbit(case.norad_id, case.attitude, tle_text, rng)
    effects = [
        _scaled_effect(n, m, rng) for n, m in zip(case.effects, case.magnitudes, strict=True)
    ]
    return _world_and_data(
        tle,
        start,
        attitude,
        effects,
        rng,
        n_orbits=n_orbits,
        cadence_s=cadence_s,
        crust_model=crust_model,
    )


def run_compound_case(
    case: CompoundCase,
    *,
    tle_text: str,
    n_orbits: float = 4.0,
    cadence_s: float = 10.0,
    crust_model: str | None = "LCS-1",
) -> dict[str, Any]:
    """Simulate a world with several effects, diagnose it blind, score found / spurious effects.

    An injected effect is *observable* when removing every injected field but its own leaves a
    held-out gap of at least ``OBSERVABLE_GAIN`` over removing them all (perfect oracle); recall
    counts the observable ones. A selected effect listed as indistinguishable from an injected one
    (or the reverse) counts as found, not as spurious.
    """
    from orbitcal.diagnose.effects import DiagnosisData

    t0 = time.perf_counter()
    world, data = simulate_compound_world(
        case, tle_text=tle_text, n_orbits=n_orbits, cadence_s=cadence_s, crust_model=crust_model
    )
    att = reviewed(data, attribute(data, split_tests=False))  # issue 25: honesty.review
    elapsed = time.perf_counter() - t0

    a_sensor = np.asarray(world.sensor.a_matrix)
    injected = {k: v @ a_sensor.T for k, v in world.injected_body_nt.items()}

    def clean_rms(keep: str | None) -> float:
        removed = sum((v for k, v in injected.items() if k != keep), np.zeros_like(data.b_raw_nt))
        clean = DiagnosisData(
            t_utc_s=data.t_utc_s,
            b_raw_nt=data.b_raw_nt - removed,
            b_ref_body_nt=data.b_ref_body_nt,
            rot_itrs_to_body=data.rot_itrs_to_body,
            r_itrs_km=data.r_itrs_km,
        )
        fit = fit_joint(clean, att.train, [])
        return norm_rms_nt((clean.b_raw_nt - fit.predict_nt(clean))[att.holdout])

    floor = clean_rms(None)
    observable = {n: bool(clean_rms(n) >= floor * (1.0 + OBSERVABLE_GAIN)) for n in case.effects}
    twins: dict[str, set[str]] = {}
    for e in att.effects:
        for other in e.params.get("indistinguishable_from", []) if e.significant else []:
            twins.setdefault(e.name, set()).add(other)
            twins.setdefault(other, set()).add(e.name)
    selected = list(att.selected)
    injected_names = set(case.effects)

    def matches(name: str) -> bool:
        return name in injected_names or bool(twins.get(name, set()) & injected_names)

    found = {n: (n in selected or bool(twins.get(n, set()) & set(selected))) for n in case.effects}
    spurious = [s for s in selected if not matches(s)]
    return {
        "index": case.index,
        "effects": list(case.effects),
        "magnitudes": list(case.magnitudes),
        "attitude": case.attitude,
        "norad_id": case.norad_id,
        "seed": case.seed,
        "verdict": att.verdict,
        "verdict_confidence": att.verdict_confidence,
        "selected": selected,
        "implausible": sorted(att.implausible),
        "found": found,
        "observable": observable,
        "spurious": spurious,
        "verdict_hit": matches(att.verdict),
        "baseline_holdout_rms_nt": att.baseline_rms_nt,
        "final_holdout_rms_nt": att.final_rms_nt,
        "perfect_holdout_rms_nt": floor,
        "seconds": elapsed,
    }


def summarise_compound(results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Recall of the observable injected effects, spurious effects per world, verdict hits."""
    res = list(results)
    obs = [(r, n) for r in res for n in r["effects"] if r["observable"][n]]
    per: dict[str, dict[str, Any]] = {}
    for r, n in obs:
        entry = per.setdefault(n, {"injected_observable": 0, "found": 0})
        entry["injected_observable"] += 1
        entry["found"] += int(r["found"][n])
    for entry in per.values():
        entry["recall"] = entry["found"] / entry["injected_observable"]
    spurious_names: dict[str, int] = {}
    for r in res:
        for s in r["spurious"]:
            spurious_names[s] = spurious_names.get(s, 0) + 1
    return {
        "worlds": len(res),
        "worlds_2": sum(1 for r in res if len(r["effects"]) == 2),
        "worlds_3": sum(1 for r in res if len(r["effects"]) == 3),
        "injected": sum(len(r["effects"]) for r in res),
        "injected_observable": len(obs),
        "recall": float(np.mean([r["found"][n] for r, n in obs])) if obs else float("nan"),
        "recall_all_injected": float(np.mean([r["found"][n] for r in res for n in r["effects"]]))
        if res
        else float("nan"),
        "worlds_with_spurious": float(np.mean([bool(r["spurious"]) for r in res]))
        if res
        else float("nan"),
        "spurious_per_world": float(np.mean([len(r["spurious"]) for r in res]))
        if res
        else float("nan"),
        "verdict_among_injected": float(np.mean([r["verdict_hit"] for r in res]))
        if res
        else float("nan"),
        "spurious_by_effect": spurious_names,
        "per_effect": per,
        "seconds_total": float(sum(r["seconds"] for r in res)),
    }


def run_compound_benchmark(
    n_cases: int,
    *,
    seed: int,
    tle_text: str,
    n_orbits: float = 4.0,
    cadence_s: float = 10.0,
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Run ``n_cases`` compound worlds; returns ``{"summary", "cases", "settings"}``."""
    from orbitcal.blas import one_blas_thread

    results = []
    with one_blas_thread():
        for case in plan_compound_cases(n_cases, seed=seed):
            out = run_compound_case(case, tle_text=tle_text, n_orbits=n_orbits, cadence_s=cadence_s)
            results.append(out)
            if progress is not None:
                progress(case.index, out)
    return {
        "summary": summarise_compound(results),
        "cases": results,
        "settings": {
            "n_cases": n_cases,
            "seed": seed,
            "n_orbits": n_orbits,
            "cadence_s": cadence_s,
            "effects_per_world": [2, 3],
            "magnitude_index": list(COMPOUND_MAGNITUDE_INDEX),
            "magnitudes": list(MAGNITUDES),
            "magnitudes_by_effect": {k: list(v) for k, v in MAGNITUDES_BY_EFFECT.items()},
            "attitudes": list(ATTITUDES),
            "norad_ids": list(NORAD_IDS),
        },
    }
