"""The second look: after the review withdraws a selected effect whose gain it does not trust,
the selection runs again without it (:func:`orbitcal.diagnose.api._attribute_reviewed`).

The pieces one by one: a candidate the selection must not choose is scored alone but never
chosen (:func:`orbitcal.diagnose.attribution.attribute`, ``excluded``); which withdrawals call
for a second look, and the twins that go with them
(:func:`orbitcal.diagnose.honesty.second_look_exclusions`); and what the first review said of
the excluded effects is kept in the second's (:func:`orbitcal.diagnose.honesty.with_earlier`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.api import _attribute_reviewed
from orbitcal.diagnose.attribution import attribute
from orbitcal.diagnose.gap import refusal
from orbitcal.diagnose.honesty import (
    Review,
    _Final,
    review,
    second_look_exclusions,
    with_earlier,
)
from orbitcal.diagnose.honesty_report import SECOND_LOOK_TWIN, _honesty_section, _mark_withdrawn
from orbitcal.diagnose.options import DiagnosisOptions

pytestmark = pytest.mark.usefixtures("single_thread_blas")  # tests/conftest.py


def _review(**kw: Any) -> Review:
    final = _Final([], None, np.zeros((4, 3)), 1.0)
    return Review(
        keep=kw.pop("keep", []), residues=[], withdrawn=[], fell_back=False, final=final, **kw
    )


class _Score:
    def __init__(self, name: str, twins: list[str]) -> None:
        self.name = name
        self.params = {"indistinguishable_from": twins} if twins else {}


class _Att:
    def __init__(self, effects: list[_Score], *, has_prior: bool = False) -> None:
        self.effects = effects
        self.has_prior = has_prior  # with a prior nothing is inseparable


def test_an_excluded_candidate_is_scored_but_never_chosen() -> None:
    data = make_world("temperature", 2.0, attitude="tumbling", seed=4).data
    first = attribute(data)
    assert first.verdict == "temperature", first.verdict
    again = attribute(data, excluded=["temperature"])
    assert "temperature" not in again.selected
    scored = {e.name: e for e in again.effects}
    assert "temperature" in scored and not scored["temperature"].significant
    assert "temperature" not in again.dropped  # not a backward-step drop


@pytest.mark.parametrize(
    ("kw", "expected"),
    [
        # withdrawn on correlated chunks with a gap left: a second look, its twin excluded too
        ({"correlated": ["time_offset"], "gap_unexplained": True}, ["time_offset", "orbit_error"]),
        ({"wander": {"sun_driven": (3.0, 2.0)}, "gap_unexplained": True}, ["sun_driven"]),
        ({"immaterial": ["nonlinearity"], "gap_unexplained": True}, ["nonlinearity"]),
        # at the noise floor there is nothing left to find
        ({"correlated": ["time_offset"], "gap_unexplained": False}, []),
        # withdrawn for what the span cannot tell (the calibration, no eclipse): no second look
        ({"inseparable": ["temperature"], "gap_unexplained": True}, []),
        ({"unlit": ["sun_driven"], "gap_unexplained": True}, []),
        # currents are judged by their own test, never excluded
        ({"correlated": ["field_aligned_currents"], "gap_unexplained": True}, []),
    ],
)
def test_which_withdrawals_call_for_a_second_look(kw: dict[str, Any], expected: list[str]) -> None:
    att = _Att([_Score("time_offset", ["orbit_error"]), _Score("sun_driven", [])])
    names, twin_of = second_look_exclusions(att, _review(**kw))  # type: ignore[arg-type]
    assert names == expected
    assert twin_of == ({"orbit_error": "time_offset"} if "orbit_error" in expected else {})


def test_a_possible_residue_calls_for_a_second_look_and_keeps_its_test() -> None:
    residue = {"effect": "attitude_error", "possible_residue": True, "gain": 0.1, "p_value": 0.2}
    kept = {"effect": "magnetorquer", "possible_residue": False, "gain": 0.5, "p_value": 1e-6}
    first = _review(keep=["magnetorquer"], gap_unexplained=True)
    first.residues.extend([residue, kept])
    excluded, twin_of = second_look_exclusions(_Att([]), first)  # type: ignore[arg-type]
    assert excluded == ["attitude_error"] and twin_of == {}
    second = _review(keep=["magnetorquer", "sun_driven"], gap_unexplained=False)
    merged = with_earlier(second, first, excluded, twin_of)
    assert merged.keep == ["magnetorquer", "sun_driven"]
    assert merged.residues == [residue]  # the excluded effect's test, not the others'
    assert not merged.gap_unexplained


def test_with_earlier_keeps_the_excluded_effects_statuses() -> None:
    first = _review(
        correlated=["sun_driven"],
        wander={"time_offset": (12.2, 2.5), "crustal_field": (1.0, 2.0)},
        immaterial=["nonlinearity"],
        gap_unexplained=True,
    )
    second = _review(keep=["attitude_error"], correlated=["magnetorquer"])
    excluded = ["sun_driven", "time_offset", "nonlinearity", "orbit_error"]
    merged = with_earlier(second, first, excluded, {"orbit_error": "time_offset"})
    assert merged.second_look == excluded
    assert merged.second_look_twins == {"orbit_error": "time_offset"}
    assert merged.correlated == ["sun_driven", "magnetorquer"]
    assert merged.wander == {"time_offset": (12.2, 2.5)}
    assert merged.immaterial == ["nonlinearity"]
    assert merged.keep == ["attitude_error"]
    # the report: the twin is withdrawn with its reason, and the honesty section says what ran
    report: dict[str, Any] = {
        "effects": [
            {"name": n, "significant": False, "status": "not significant"}
            for n in [*excluded, "magnetorquer", "attitude_error"]
        ]
    }
    _mark_withdrawn(report, _Att([], has_prior=True), merged)  # type: ignore[arg-type]
    twin = next(e for e in report["effects"] if e["name"] == "orbit_error")
    assert twin["status"] == SECOND_LOOK_TWIN
    assert "time_offset" in refusal(twin)
    section = _honesty_section(merged)
    assert section["second_look"] == excluded
    assert (
        "ran again without sun_driven, time_offset, nonlinearity (and its twin orbit_error)"
        in (section["second_look_statement"])
    )


def test_without_a_withdrawal_there_is_no_second_look() -> None:
    """A world whose selected effect stands: the same attribution and review as without the
    second look."""
    data = make_world("magnetorquer", attitude="tumbling", seed=3).data
    att, rv = _attribute_reviewed(data, DiagnosisOptions(), None)
    plain = attribute(data)
    assert att.selected == plain.selected
    assert rv.keep == review(data, plain).keep


@pytest.mark.parametrize(
    ("second_keep", "taken"),
    [
        (["attitude_error"], True),  # a candidate the selection passed over: the second look
        (["field_aligned_currents"], False),  # named by its own regional test: not one
        (["attitude_error", "field_aligned_currents"], False),
        ([], False),  # nothing new
    ],
)
def test_the_second_selection_is_kept_only_for_a_passed_over_candidate(
    monkeypatch: pytest.MonkeyPatch, second_keep: list[str], taken: bool
) -> None:
    """The decision of :func:`_attribute_reviewed`, with the attribution and review replaced by
    what each round returns (11700 no. 4 of the independent worlds named auroral currents of
    nothing injected when any new effect was taken)."""
    import orbitcal.diagnose.attribution as attribution
    import orbitcal.diagnose.honesty as honesty

    first_att = _Att([_Score("time_offset", [])])
    second_att = _Att([])
    calls: list[tuple[str, ...]] = []

    def fake_attribute(data: object, **kw: Any) -> _Att:
        calls.append(tuple(kw.get("excluded", ())))
        return first_att if len(calls) == 1 else second_att

    reviewed_without: list[tuple[str, ...]] = []

    def fake_review(data: object, att: _Att, excluded: Sequence[str] = ()) -> Review:
        reviewed_without.append(tuple(excluded))
        if att is first_att:
            return _review(correlated=["time_offset"], gap_unexplained=True)
        return _review(keep=list(second_keep), gap_unexplained=False)

    monkeypatch.setattr(attribution, "attribute", fake_attribute)
    monkeypatch.setattr(honesty, "review", fake_review)
    att, rv = _attribute_reviewed(None, DiagnosisOptions(), None)  # type: ignore[arg-type]
    assert calls == [(), ("time_offset",)]
    # the second review knows what its selection ran without (the rotation test names none)
    assert reviewed_without == [(), ("time_offset",)]
    assert (att is second_att) is taken
    assert rv.second_look == (["time_offset"] if taken else [])
