"""The report page's first screen read back against the report's JSON (issue 47).

Each claim the first screen makes is parsed from the HTML and checked against the numbers of the
JSON it was drawn from: the verdict, its size (value and 90 % interval, and whether it is said to
be separable from the calibration), how sure (at most three short lines; a percentage only for a
probability; the held-out RMS before and after), the next step (one per selected effect, a
time-tag correction with the fitted offset's sign), and no JSON key anywhere on the page. The
last test does this over worlds simulated and diagnosed end to end (a time-tag error that cannot
be told from an orbit error, a temperature coefficient, torquer leakage, nothing injected); the
fast ones over the committed report and variants of it (a probability and a confirmation block
as the new diagnosis adds them, a size that is not measured).
"""

from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from orbitcal.diagnose.claims import size_measured
from orbitcal.diagnose.first_screen import EFFECT_TITLES, format_number
from orbitcal.diagnose.html_report import report_html

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "diagnosis_report_time_offset.json"
TLE = ROOT / "tests" / "authorities" / "swarm_iss_real_tles.tle"
SNAKE = re.compile(r"\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b")


class _Screen(HTMLParser):
    """The claims of the first screen: text per ``data-claim`` element, their attributes, the
    How-sure lines, the next steps, and the page's whole text (``<details>`` included)."""

    def __init__(self) -> None:
        super().__init__()
        self.claims: dict[str, str] = {}
        self.attrs: dict[str, dict[str, str | None]] = {}
        self.lines: list[str] = []
        self.steps: list[str] = []
        self.text: list[str] = []
        self._open: list[tuple[str, str | None, str | None]] = []  # (tag, claim, class)
        self._skip = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag in ("style", "script"):
            self._skip += 1
        claim = a.get("data-claim")
        if claim:
            self.claims[claim] = ""
            self.attrs[claim] = a
        if tag == "div" and a.get("class") == "line":
            self.lines.append("")
        if tag == "li" and any(c == "next-step" for _, c, _ in self._open):
            self.steps.append("")
        if tag not in ("br", "img", "meta", "link", "col", "input"):
            self._open.append((tag, claim, a.get("class")))

    def handle_endtag(self, tag: str) -> None:
        if tag in ("style", "script"):
            self._skip -= 1
        while self._open:
            top = self._open.pop()
            if top[0] == tag:
                break

    def handle_data(self, data: str) -> None:
        if self._skip:
            return
        self.text.append(data)
        for tag, claim, cls in self._open:
            if claim:
                self.claims[claim] += data
            if tag == "div" and cls == "line":
                self.lines[-1] += data
            if tag == "li" and any(c == "next-step" for _, c, _ in self._open):
                self.steps[-1] += data
                break


def _screen(page: str) -> _Screen:
    s = _Screen()
    s.feed(page)
    s.claims = {k: " ".join(v.split()) for k, v in s.claims.items()}
    s.lines = [" ".join(x.split()) for x in s.lines]
    s.steps = [" ".join(x.split()) for x in s.steps]
    return s


def check_first_screen(report: dict[str, Any]) -> _Screen:
    """Every first-screen claim of ``report``'s page agrees with ``report``'s numbers."""
    page = report_html(report)
    s = _screen(page)
    verdict = str(report["verdict"])
    effects = {e["name"]: e for e in report["effects"]}
    # verdict
    assert s.attrs["verdict"]["data-effect"] == verdict
    if verdict == "none":
        assert s.claims["verdict"] == "No unmodelled effect found"
        assert "size" not in s.claims
    else:
        assert s.claims["verdict"].endswith(f"({verdict})"), s.claims["verdict"]
        _check_size(report, effects[verdict], s)
    _check_how_sure(report, s)
    _check_next_steps(report, s)
    # no JSON key on the page: snake_case words are the catalogue's effect names only
    keys = set(SNAKE.findall(" ".join(s.text))) - set(EFFECT_TITLES)
    assert not keys, keys
    return s


def _numbers(text: str) -> list[str]:
    return re.findall(r"−?\d[\d,]*(?:\.\d+)?(?:e−?\d+)?", text)


def _check_size(report: dict[str, Any], entry: dict[str, Any], s: _Screen) -> None:
    size = s.claims["size"]
    separable = report.get("separable")
    says_inseparable = "cannot be separated" in size
    measured = size_measured(entry, age_days=(report.get("data") or {}).get("element_age_days"))
    # separable: said as the JSON says it, and only when no parameter measures the size
    assert s.attrs["size"]["data-separable"] == ("no" if says_inseparable else "yes")
    if separable is not None:
        assert says_inseparable == (separable is False), (size, separable)
    assert not (says_inseparable and measured), size
    if "measures its size" in size or measured:
        assert measured and not says_inseparable
        # the value and interval on screen are the JSON's, to three digits
        name = next(
            n
            for n, iv in (entry.get("param_intervals_90") or {}).items()
            if f"= {format_number(entry['params'][n])}" in size
        )
        lo, hi = entry["param_intervals_90"][name]
        assert f"90 %: {format_number(lo)} … {format_number(hi)}" in size
        a = entry.get("absorbed_by_calibration_fraction")
        if isinstance(a, float) and a >= 0.5:
            assert f"({a:.1%})" in size


def _check_how_sure(report: dict[str, Any], s: _Screen) -> None:
    lines = s.lines
    assert 1 <= len(lines) <= 3, lines
    assert all(len(x) <= 120 for x in lines), lines
    probability = report.get("verdict_probability")
    percents = [x for x in lines if "%" in x]
    if isinstance(probability, float):
        assert percents == [lines[0]] and f"{100 * probability:.0f} %" in lines[0]
    else:
        assert not percents, lines  # a resampling frequency is no probability
    joined = " ".join(lines)
    confirmation = report.get("confirmation")
    model = report.get("model") or {}
    by_events = (model.get("event_confirmations") or {}).get(report["verdict"])
    if by_events and report["verdict"] in model.get("named", []):
        confirmation = by_events  # an effect named within the final block's events
    if isinstance(confirmation, dict):
        before, after = confirmation["holdout_rms_before_nt"], confirmation["holdout_rms_after_nt"]
        assert f"{format_number(before)} → {format_number(after)} nT" in joined
    elif report["verdict"] != "none":
        before, after = report["baseline"]["holdout_rms_nt"], report["final"]["holdout_rms_nt"]
        assert f"{format_number(before)} → {format_number(after)} nT" in joined
    else:
        assert f"{format_number(report['baseline']['holdout_rms_nt'])} nT" in joined
    twins = re.search(r"cannot be told apart from ([a-z_, ]+)\.", joined)
    if twins:
        entry = next(e for e in report["effects"] if e["name"] == report["verdict"])
        named = {str(t) for t in entry["params"].get("indistinguishable_from") or []}
        named |= {c["name"] for c in report.get("confounded_with") or []}
        assert set(twins.group(1).split(", ")) <= named


def _check_next_steps(report: dict[str, Any], s: _Screen) -> None:
    selected = [e for e in report["effects"] if e.get("significant")]
    steps = s.steps
    assert steps
    for e in selected:
        (step,) = [x for x in steps if x.startswith(f"{e['name']}: ")]
        if e["name"] == "time_offset":
            dt = float(e["params"]["dt_s"])
            assert f"add {format_number(dt)} s to the magnetometer time tags" in step
            late = "late" if dt < 0 else "early"  # dt_s: the stamp t holds the field of t + dt
            assert f"they run {format_number(abs(dt))} s {late}" in step
            assert "check the time-tagging chain" in step
    if report["verdict"] == "none":
        assert not any(x.split(":")[0] in EFFECT_TITLES for x in steps)


# ---- the committed report and variants of it -------------------------------------------------


@pytest.fixture
def report() -> dict[str, Any]:
    return json.loads(FIXTURE.read_text())  # type: ignore[no-any-return]


def test_the_committed_report_first_screen_agrees_with_its_json(report: dict[str, Any]) -> None:
    s = check_first_screen(report)
    # 99.6 % of its field absorbed, yet dt within 2 ms: measured, not "cannot be separated"
    assert "most of its field (99.6%) looks like a change of the 12" in s.claims["size"]
    assert "add −0.497 s to the magnetometer time tags" in s.claims["next-step"]


def test_a_probability_and_a_confirmation_are_what_how_sure_states(
    report: dict[str, Any],
) -> None:
    new = copy.deepcopy(report)
    new["verdict_probability"] = 0.973
    new["confirmation"] = {
        "holdout_rms_before_nt": 15.21,
        "holdout_rms_after_nt": 2.114,
        "p_value": 1.2e-6,
    }
    s = check_first_screen(new)
    assert s.lines[0] == "Probability 97 % that time_offset is present."
    assert s.lines[1] == (
        "On a final block no selection used: held-out RMS 15.2 → 2.11 nT (p = 1.2e−06)."
    )


def test_an_effect_named_within_the_final_blocks_events_states_their_numbers(
    report: dict[str, Any],
) -> None:
    """An effect the model core names by its events (auroral currents, whose amplitudes change
    from crossing to crossing): how sure states the within-event confirmation's RMS, not the
    forecast confirmation's."""
    new = copy.deepcopy(report)
    new["verdict_probability"] = 1.0
    new["confirmation"] = {
        "holdout_rms_before_nt": 30.0,
        "holdout_rms_after_nt": 30.0,
        "p_value": 1.0,
    }
    new["model"] = {
        "named": ["time_offset"],
        "chosen": [],
        "event_confirmations": {
            "time_offset": {
                "holdout_rms_before_nt": 30.02,
                "holdout_rms_after_nt": 9.234,
                "p_value": 0.043,
            }
        },
    }
    s = check_first_screen(new)
    assert s.lines[1] == (
        "Within the final block's events, each fitted on part of itself: RMS 30.0 → 9.23 nT "
        "(p = 0.043)."
    )


def test_a_size_no_interval_measures_is_said_not_separable(report: dict[str, Any]) -> None:
    wide = copy.deepcopy(report)
    entry = wide["effects"][0]
    entry["param_intervals_90"] = {"dt_s": [-5.0, 0.2], "dt_squared_s2": [0.0, 25.0]}
    wide["separable"] = False
    wide["separation"] = [
        {"effect": "time_offset", "absorbed_fraction": 0.9964, "would_separate": "a prior"}
    ]
    s = check_first_screen(wide)
    assert "cannot be separated from the calibration" in s.claims["size"]
    assert "(to measure it: a prior)" in s.claims["size"]
    # a size the report measures is never called inseparable, whatever an older JSON's list says
    old = copy.deepcopy(report)
    old["separation"] = wide["separation"]
    assert "cannot be separated" not in report_html(old)


# ---- worlds diagnosed end to end -------------------------------------------------------------


def _diagnosed(tmp: Path, effect: str | None) -> dict[str, Any]:
    out = tmp / (effect or "none")
    cmd = [
        sys.executable, "-m", "orbitcal", "simulate", "--tle", str(TLE), "--norad", "25544",
        "--start", "2022-08-02T00:00:00Z", "--duration-s", "21600", "--cadence-s", "10",
        "--attitude", "tumbling", "--seed", "4", "--out", str(out),
        *(["--effect", effect] if effect else []),
    ]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True, cwd=tmp)
    report = tmp / f"{effect}.json"
    cmd = [
        sys.executable, "-m", "orbitcal", "diagnose", str(out / "telemetry.csv"),
        "--tle", str(out / "spacecraft.tle"), "--out", str(report),
    ]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True, cwd=tmp)
    return json.loads(report.read_text())  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("effect", "verdict"),
    [("time_offset", "time_offset"), ("temperature", "temperature"),
     ("magnetorquer", "magnetorquer"), (None, "none")],
)  # fmt: skip
def test_first_screen_agrees_with_the_json_over_worlds(
    tmp_path: Path, effect: str | None, verdict: str
) -> None:
    report = _diagnosed(tmp_path, effect)
    assert report["verdict"] == verdict
    s = check_first_screen(report)
    if effect == "time_offset":
        # the README's world: dt ≈ −0.498 s, absorbed 99.6 %, and an orbit error its twin
        assert report["separable"] is True and report["separation"] == []
        assert "cannot be told apart from orbit_error" in s.lines[-1]
        assert not report["effects"][0].get("inseparable")
    if verdict == "none":
        assert s.steps[0].startswith("nothing to correct")


def test_each_effect_states_its_probability_when_the_report_has_one(
    report: dict[str, Any],
) -> None:
    new = copy.deepcopy(report)
    for k, e in enumerate(new["effects"]):
        e["probability"] = 0.97 if k == 0 else 0.004
    page = report_html(new)
    assert "probability 97 % that it is present; held-out RMS 16.0 → 2.08 nT" in page
    assert "not significant (probability 0 %)" in page
    assert "probability" not in report_html(report)
