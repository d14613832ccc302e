"""Several effects at once: the stepwise selection of :func:`orbitcal.diagnose.attribute`.

Fixed worlds of the compound benchmark (``orbitcal bench diagnose --compound``, plan seed 1) on
which the forward-only selection of 2026-11-23 failed, each for one reason the stepwise selection
addresses; and the named steps (:class:`orbitcal.diagnose.attribution.Selection`) one by one.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.attribution import (
    Selection,
    attribute,
    fit_joint,
    time_blocks,
)
from orbitcal.diagnose.bench import CompoundCase, run_compound_case
from orbitcal.diagnose.effects import get_effect
from orbitcal.diagnose.options import AttributionOptions
from orbitcal.metrics import norm_rms_nt

pytestmark = pytest.mark.usefixtures("single_thread_blas")  # tests/conftest.py


def _found_exactly(result: dict[str, object], names: set[str]) -> None:
    assert set(result["selected"]) == names, result  # type: ignore[call-overload]
    assert result["spurious"] == [], result
    assert all(result["found"].values()), result  # type: ignore[attr-defined]


def test_two_effects_that_pass_only_together_are_both_found(real_tles_text: str) -> None:
    """A thermal offset and a bias step (nadir): fitted alone, each leaves the other's misfit and
    neither passes the held-out test (temperature p = 0.79, drift p = 0.08); together both are
    significant. Forward-only selection named nothing (held-out 19.5 nT left); the pair step
    finds both and nothing else."""
    case = CompoundCase(
        18, ("temperature", "parameter_drift"), (1.0, 1.0), "nadir", 39451, 1625994511
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, {"temperature", "parameter_drift"})
    assert out["final_holdout_rms_nt"] < 0.5 * out["baseline_holdout_rms_nt"]


def test_a_flexible_stand_in_is_swapped_for_the_effect_it_stood_for(real_tles_text: str) -> None:
    """A 1 s time-tag error under a doubled nonlinearity and a thermal offset (tumbling ISS): at
    the first step the time offset needs dt = -8.5 s (implausible, the nonlinearity is still in the
    residual) and the 9-parameter orbit error stands in for it; the forward-only selection kept
    orbit_error. Chosen again beside the other two, the time offset wins (tie by training BIC)."""
    case = CompoundCase(
        17,
        ("time_offset", "nonlinearity", "temperature"),
        (2.0, 2.0, 1.0),
        "tumbling",
        25544,
        675405135,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, {"time_offset", "nonlinearity", "temperature"})
    assert out["verdict"] in case.effects


def test_recovering_ring_current_leaves_no_room_for_a_drift(real_tles_text: str) -> None:
    """A storm's ring current decaying with a 5.6 h recovery time and a magnetorquer (nadir):
    with a linear trend only, the external model left a residual that a bias step explained
    (drift named, never injected); the recovery-phase variant and the swap pass leave both
    effects and no drift."""
    case = CompoundCase(
        6, ("magnetorquer", "external_field"), (1.0, 2.0), "nadir", 39452, 911820705
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, {"magnetorquer", "external_field"})


def test_currents_that_change_from_crossing_to_crossing_are_found_beside_others(
    real_tles_text: str,
) -> None:
    """Doubled auroral currents beside an orbit error and a Sun-driven field (tumbling, polar):
    the crossing strengths change (0.5-1.5x), so the held-out test fails the currents model
    (85 -> 61 nT but p = 0.02); the regional test ran only when nothing was selected and fitted
    one set of bumps to every crossing (dawn and dusk signs cancel: 199 -> 212 nT). Each leg of
    each crossing fitted alone predicts its held-out folds (199 -> 5 nT): all three are found."""
    case = CompoundCase(
        27,
        ("orbit_error", "sun_driven", "field_aligned_currents"),
        (2.0, 2.0, 2.0),
        "tumbling",
        39453,
        291713023,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    assert set(case.effects) <= set(out["selected"]), out
    assert out["spurious"] == [], out


def test_other_effects_are_judged_on_quiet_latitudes_when_currents_are_found(
    real_tles_text: str,
) -> None:
    """Doubled auroral currents (110 nT held-out RMS) beside a Sun-driven field and a bias step
    (tumbling, polar): the currents' held-out part, different at every crossing, swamped both
    smaller effects' held-out tests and only the currents were named (110 -> 110 nT). Once the
    regional test finds the currents in the calibration's residual, the others are fitted and
    judged on |magnetic latitude| < 50 deg: all three are found. The final model (the currents'
    model fitted beside them on every sample) leaves the crossings' unpredictable part only."""
    case = CompoundCase(
        23,
        ("sun_driven", "parameter_drift", "field_aligned_currents"),
        (1.0, 1.0, 2.0),
        "tumbling",
        39452,
        1434216453,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))
    assert out["final_holdout_rms_nt"] < 0.7 * out["baseline_holdout_rms_nt"], out


def test_an_effect_out_of_range_alone_enters_a_pair_inside_it(real_tles_text: str) -> None:
    """A bias step, a thermal offset and auroral currents (tumbling): beside the currents the
    drift alone needs 165 nT/day (implausible) and the temperature alone is not significant
    (p = 0.012 at a level of 0.005, the step still in the residual); the pair step now tries
    implausible candidates too and the pair passes with both inside their ranges."""
    case = CompoundCase(
        21,
        ("parameter_drift", "temperature", "field_aligned_currents"),
        (1.0, 1.0, 1.0),
        "tumbling",
        39451,
        1157162241,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))


def test_an_attitude_error_in_a_pair_is_scanned_beside_its_partner(real_tles_text: str) -> None:
    """A 2 s time-tag error, a ring-current field and an attitude error (nadir): no single
    candidate passes (the attitude periods scanned on the calibration-only residual make the
    held-out RMS 60 nT from 35), and nothing was named. In the pair step the attitude error is
    scanned again beside its partner (time offset + attitude: 12 nT), the third follows."""
    case = CompoundCase(
        17,
        ("time_offset", "external_field", "attitude_error"),
        (2.0, 1.0, 1.0),
        "nadir",
        39453,
        763929847,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    assert all(out["found"].values()), out
    assert out["spurious"] == [], out
    assert out["final_holdout_rms_nt"] < 1.5 * out["perfect_holdout_rms_nt"]


def test_a_pair_member_at_its_bound_is_fitted_in_another_variant_beside_the_other(
    real_tles_text: str,
) -> None:
    """A doubled nonlinearity and a doubled storm field (nadir): alone, the ring-current model
    needs an RC scale of 3.6 (implausible) and the nonlinearity is not significant (p = 0.008 at
    0.0045); beside the nonlinearity, the RC variant chosen alone pins its scale at the lower
    bound 0.2, and the pair was dropped. Its variant chosen again beside the partner fits inside
    its range (held-out 3.8 nT from 58.9; nothing was named)."""
    case = CompoundCase(
        42, ("nonlinearity", "external_field"), (2.0, 2.0), "nadir", 39451, 896692739
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))
    assert out["final_holdout_rms_nt"] < 1.2 * out["perfect_holdout_rms_nt"]


@pytest.mark.parametrize(
    "case",
    [
        # attitude error, temperature x2, nonlinearity x2 (ISS): 60 nT held out, nothing named
        CompoundCase(
            13,
            ("attitude_error", "temperature", "nonlinearity"),
            (1.0, 2.0, 2.0),
            "nadir",
            25544,
            1715383800,
        ),
        # doubled currents, attitude error and nonlinearity (Swarm): 92 nT, nothing named
        CompoundCase(
            9,
            ("field_aligned_currents", "attitude_error", "nonlinearity"),
            (2.0, 2.0, 2.0),
            "nadir",
            39453,
            545672980,
        ),
    ],
    ids=["temperature", "currents"],
)
def test_an_attitude_error_is_scanned_beside_two_effects_when_no_pair_passes(
    case: CompoundCase, real_tles_text: str
) -> None:
    """Three effects with a doubled nonlinearity in a nadir attitude: its cross-track terms are
    ill-determined (+-150 nT from the data alone) and take up the attitude error's field, so
    alone and in every pair the nonlinearity leaves its range, and the attitude periods scanned
    on the calibration's residual are wrong. The triple step scans the attitude error beside the
    best screened pairs; with the nonlinearity's prior (0 +- 250 nT) all three fit inside their
    ranges and pass (plan seeds 131 and 132 of the compound benchmark)."""
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))
    assert out["final_holdout_rms_nt"] < 3.0 * out["perfect_holdout_rms_nt"]


def test_three_effects_that_pass_only_together_are_found(real_tles_text: str) -> None:
    """A 4 km along-track orbit error, a nonlinearity and a thermal offset (nadir): alone the
    nonlinearity needs a cross-track cubic term of 1,865 nT (implausible) and no pair passes;
    nothing was named at 23.6 nT. The triple step screens the triples of the candidates in the
    residual and the three pass together at the noise floor."""
    case = CompoundCase(
        9,
        ("orbit_error", "nonlinearity", "temperature"),
        (4.0, 1.0, 1.0),
        "nadir",
        39452,
        324315521,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))
    assert out["final_holdout_rms_nt"] < 1.2 * out["perfect_holdout_rms_nt"]


def test_a_pair_is_tried_again_with_each_form_chosen_beside_the_other(
    real_tles_text: str,
) -> None:
    """A doubled bias step and an attitude error (nadir): alone, the drift's step time and the
    attitude periods are chosen with the other's field in the residual and the pair fails; a
    ring-current model passing by a hair (49.9 -> 49.6 nT) was named instead. Tried again with
    the step time chosen beside the attitude error and the periods scanned beside the step, the
    pair passes at the noise floor."""
    case = CompoundCase(
        12, ("parameter_drift", "attitude_error"), (2.0, 1.0), "nadir", 39453, 1342886137
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))
    assert out["final_holdout_rms_nt"] < 1.2 * out["perfect_holdout_rms_nt"]


def test_a_drift_step_time_is_refined_between_the_grid_times(real_tles_text: str) -> None:
    """A doubled bias step (30 nT) with a crust and an attitude error (nadir): on the 17-point
    grid of step times (780 s apart) the nearest left a box of the step's height that the
    others took up (only the attitude error named, 26 nT left); refined by halving, the step
    time lands within the resolution and all three are found."""
    case = CompoundCase(
        17,
        ("parameter_drift", "crustal_field", "attitude_error"),
        (2.0, 2.0, 2.0),
        "nadir",
        39453,
        759894198,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))


@pytest.mark.xfail(
    strict=True,
    reason=(
        "since the attitude error has a drift and forecast-chosen periods (2026-11-27), the "
        "temperature is not found beside the bias step and the attitude error (both named, 2 of "
        "3): a known loss, traded for 17 -> 4 of 36 attitude errors missed on independent "
        "seeds 10400-10900 (benchmarks/results/diagnose_independent.md)"
    ),
)
def test_an_attitude_error_chosen_alone_is_chosen_again_with_the_others(
    real_tles_text: str,
) -> None:
    """A bias step, an attitude error and a thermal offset (nadir): the attitude error passed
    alone at the first step, its periods scanned on a residual the step still filled, and beside
    them the thermal offset did not pass (7.2 nT left, the attitude error and the drift named).
    Stuck with a scanned effect chosen, the selection runs the group
    steps again without it: the drift with the attitude error scanned beside it, then the
    thermal offset."""
    case = CompoundCase(
        43,
        ("parameter_drift", "attitude_error", "temperature"),
        (1.0, 1.0, 1.0),
        "nadir",
        25544,
        1796488990,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    _found_exactly(out, set(case.effects))


def _selection(
    effect: str, *, seed: int = 3, attitude: str = "tumbling", magnitude: float = 1.0
) -> Selection:
    data = make_world(effect, magnitude, attitude=attitude, seed=seed).data
    train, holdout, _ = time_blocks(data.t_utc_s)
    designs = {}
    for name in ("temperature", "magnetorquer", "nonlinearity", "time_offset", "orbit_error"):
        block = get_effect(name).design(data, train)
        if block is not None:
            designs[name] = block
    return Selection(data, train, holdout, designs)


def test_backward_step_drops_an_effect_that_adds_nothing_beside_the_others() -> None:
    sel = _selection("magnetorquer")
    blocks = [sel.designs["magnetorquer"], sel.designs["nonlinearity"]]
    assert sel.backward(blocks, ["magnetorquer", "nonlinearity"]) == "nonlinearity"
    assert sel.backward(blocks[:1], ["magnetorquer"]) is None  # one effect: nothing to re-test


def test_backward_step_keeps_two_real_effects() -> None:
    """A world with a magnetorquer coupling and a thermal offset at once (the second added to a
    magnetorquer world): each is significant beside the other."""
    sel = _selection("magnetorquer")
    temp = sel.designs["temperature"]
    extra = temp.g @ np.array([3.0, -2.0, 2.5, 0.0, 0.0, 0.0])  # nT/degC offsets
    import dataclasses

    data = dataclasses.replace(sel.data, b_raw_nt=sel.data.b_raw_nt + extra)
    sel = Selection(data, sel.train, sel.holdout, sel.designs)
    blocks = [sel.designs["magnetorquer"], temp]
    assert sel.backward(blocks, ["magnetorquer", "temperature"]) is None


def test_candidate_is_judged_against_the_model_before_it() -> None:
    sel = _selection("magnetorquer")
    base = fit_joint(sel.data, sel.train, [])
    r_base = sel.data.b_raw_nt - base.predict_nt(sel.data)
    real = sel.candidate([], "magnetorquer", r_base)
    assert real.passes(0.05 / len(sel.designs))
    assert real.holdout_rms_nt < norm_rms_nt(r_base[sel.holdout])
    # with the coupling in the model, nonlinearity has nothing left to explain
    after = sel.candidate([real.block], "nonlinearity", real.residual_nt, real.fit)
    assert not after.passes(0.05 / len(sel.designs))


def test_pick_names_the_simpler_of_two_models_the_held_out_data_cannot_tell_apart() -> None:
    """A time-tag error under a steady spin, on a propagated orbit: the along-track error model
    explains the same held-out data; the training BIC names one and lists the other."""
    sel = _selection("time_offset", seed=4, magnitude=0.3)
    base = fit_joint(sel.data, sel.train, [])
    r_base = sel.data.b_raw_nt - base.predict_nt(sel.data)
    cands = [sel.candidate([], n, r_base) for n in ("time_offset", "orbit_error")]
    assert all(c.passes(0.05 / 2) for c in cands)
    best, twins = sel.pick(cands)
    other = ({"time_offset", "orbit_error"} - {best.name}).pop()
    assert twins == [other]


def test_compound_attribution_reports_dropped_effects_separately() -> None:
    """The Attribution lists what the backward step removed; never one of the selected."""
    att = attribute(
        make_world("magnetorquer", attitude="tumbling", seed=3).data,
        options=AttributionOptions(split_tests=False),
    )
    assert att.verdict == "magnetorquer"
    assert not set(att.dropped) & set(att.selected)


def test_time_offset_standing_for_an_orbit_error_lists_it_as_indistinguishable() -> None:
    """Nadir world with a crust, a 4 km along-track orbit error and a Sun pattern (compound seed
    42, world 3). A time offset standing for the along-track shift must list the orbit error as
    indistinguishable (before: a spurious time offset, the orbit missed); since the crustal
    candidate is LCS-1 above IGRF's degree 13 (its degrees 1..13 no longer take a share of the
    orbit error's field) the orbit error itself is named."""
    from orbitcal.data import real_tles_text
    from orbitcal.diagnose.bench import plan_compound_cases

    case = plan_compound_cases(50, seed=42)[3]
    assert case.effects == ("crustal_field", "orbit_error", "sun_driven")
    result = run_compound_case(case, tle_text=real_tles_text())
    assert result["found"]["orbit_error"] and not result["spurious"]
    assert "orbit_error" in result["selected"] or "time_offset" in result["selected"]


def test_an_orbit_error_hidden_beside_a_time_offset_is_listed_as_its_near_twin(
    real_tles_text: str,
) -> None:
    """A 1 s time-tag error, a doubled thermal offset and a 4 km along-track orbit error (tumbling,
    polar; compound seed 91, world 15): the time offset absorbs the orbit error's shift along the
    track, and the orbit error beside it gains less than 3 % on the held-out blocks (the Earth's
    rotation is all that is left of it). Replacing the time offset by it is worse, so the report
    named the orbit error nowhere; now it is listed as indistinguishable from the time offset."""
    case = CompoundCase(
        15,
        ("time_offset", "temperature", "orbit_error"),
        (1.0, 2.0, 4.0),
        "tumbling",
        39453,
        1250068531,
    )
    out = run_compound_case(case, tle_text=real_tles_text)
    assert {"time_offset", "temperature"} <= set(out["selected"]), out
    assert "orbit_error" not in out["selected"]
    assert all(out["found"].values()) and out["spurious"] == [], out


def test_auroral_crossings_are_cut_into_legs_at_their_highest_latitude() -> None:
    """Two crossings (a gap of 10 min between them) each split at its apex; a run whose apex is at
    its first sample stays whole."""
    from orbitcal.diagnose.attribution import fac_legs

    t = np.arange(0.0, 2000.0, 10.0)
    amlat = np.zeros(t.size)
    amlat[10:31] = 60.0 + 20.0 * np.sin(np.linspace(0.1, np.pi - 0.1, 21))  # apex at 20
    amlat[90:110] = np.linspace(85.0, 56.0, 20)  # leaves the oval from its highest latitude
    idx = np.flatnonzero(amlat > 55.0)
    legs = fac_legs(t, amlat, idx)
    assert [(int(leg[0]), int(leg[-1])) for leg in legs] == [(10, 20), (21, 30), (90, 109)]
