"""The diagnosis report's HTML page, for an AOCS engineer: the first screen answers what is wrong,
where, how sure and what to do next, with the evidence plotted; the JSON is one click away and
never on screen; numbers to three significant digits; intervals that only reach a parameter's
physical range are flagged as bound-limited; the page is drawn from the JSON alone.

The report rendered is ``tests/fixtures/diagnosis_report_time_offset.json`` (the README's first
session; see tests/fixtures/README.md). The browser test screenshots the page in Debian chromium
(``$ORBITCAL_SCREENSHOT_DIR`` keeps the PNG).
"""

from __future__ import annotations

import base64
import copy
import json
import os
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from orbitcal.diagnose.html_report import format_number, report_html

FIXTURE = Path(__file__).parent / "fixtures" / "diagnosis_report_time_offset.json"


@pytest.fixture
def report() -> dict[str, Any]:
    return json.loads(FIXTURE.read_text())  # type: ignore[no-any-return]


class _Text(HTMLParser):
    """The text a reader sees without opening anything: outside <details>, <script>, <style>."""

    def __init__(self) -> None:
        super().__init__()
        self.hidden = 0
        self.parts: list[str] = []
        self.ids: dict[str, str] = {}
        self._stack: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag in ("details", "style", "script"):
            self.hidden += 1
        ident = dict(attrs).get("id")
        self._stack.append(ident or "")
        if ident:
            self.ids[ident] = ""

    def handle_endtag(self, tag: str) -> None:
        if tag in ("details", "style", "script"):
            self.hidden -= 1
        if self._stack:
            self._stack.pop()

    def handle_data(self, data: str) -> None:
        if self.hidden == 0:
            self.parts.append(data)
        for ident in self._stack:
            if ident:
                self.ids[ident] += data


def _visible(page: str) -> _Text:
    parser = _Text()
    parser.feed(page)
    return parser


def test_first_screen_answers_what_where_how_sure_and_next(report: dict[str, Any]) -> None:
    page = report_html(report)
    seen = _visible(page)
    verdict = " ".join(seen.ids["verdict"].split())
    assert verdict == "A time-tag error of the magnetometer samples (time_offset)"
    size = " ".join(seen.ids["size"].split())
    assert size.startswith("time offset dt = −0.497 s (90 %: −0.498 … −0.496 s)")
    # 99.6 % absorbed, yet measured: said as what is absorbed, not as "cannot be separated"
    assert "most of its field (99.6%) looks like a change of the 12" in size
    assert "cannot be separated" not in page
    where = " ".join(seen.ids["where"].split())
    assert "concentrated at |magnetic latitude| 0–30°" in where
    lines = [" ".join(x.split()) for x in re.findall(r'<div class="line">(.*?)</div>', page)]
    assert 2 <= len(lines) <= 3 and all(len(x) <= 110 for x in lines), lines
    assert lines[0] == (
        "Named by the held-out test (p = 2.3e−10); it wins in every resample of the held-out "
        "blocks."
    )
    assert "16.0 → 2.08 nT" in lines[1] and "cannot be told apart from orbit_error" in lines[2]
    assert "%" not in " ".join(lines)  # the resampling frequency is no probability
    steps = " ".join(seen.ids["next-step"].split())
    assert "add −0.497 s to the magnetometer time tags (they run 0.497 s late)" in steps
    assert "check the time-tagging chain" in steps
    assert "to tell time_offset from orbit_error" in steps
    # the order on the page: the four answers, then the evidence plots, then the tables
    order = [page.index(f'id="{i}"') for i in ("verdict", "where", "how-sure", "next-step")]
    assert order == sorted(order)
    first_plot = page.index('class="evidence-plot"')
    assert order[-1] < first_plot < page.index("Selected effects")
    assert page.count('class="evidence-plot"') == len(report["evidence"]) == 3


def test_raw_json_is_one_click_away_not_on_screen(report: dict[str, Any]) -> None:
    page = report_html(report)
    seen = _visible(page)
    text = " ".join(seen.parts)
    assert '"axis_rms_nt"' not in text and "{" not in text  # no JSON on screen
    assert "<pre>" not in page  # nothing unknown in this report: no raw section at all
    href = re.search(r'id="json-link"[^>]*href="data:application/json;base64,([^"]+)"', page)
    assert href is not None
    assert json.loads(base64.b64decode(href.group(1))) == report


def test_numbers_to_three_significant_digits(report: dict[str, Any]) -> None:
    page = report_html(report)
    text = " ".join(_visible(page).parts)
    # 16.0009 nT, -0.497 s, 7.6942: shown as 16, −0.497, 7.69
    assert "16.0009" not in text and "7.6942" not in text
    assert "7.69" in text
    digits = [len(m.replace(",", "").replace(".", "").lstrip("−0")) for m in
              re.findall(r"−?\d[\d,]*\.\d+", text)]  # fmt: skip
    assert digits and max(digits) <= 4, max(digits)
    assert format_number(2147.7644) == "2,148"
    assert format_number(-0.4986) == "−0.499"
    assert format_number(1.6e-5) == "1.60e−05"
    assert format_number(None) == "–"


def test_bound_limited_intervals_are_not_shown_as_measured(report: dict[str, Any]) -> None:
    sun = next(e for e in report["effects"] if e["name"] == "sun_driven")
    assert all(iv == [-500.0, 500.0] for iv in sun["param_intervals_90"].values())
    page = report_html(report)
    row = re.search(r"<tr><td>sun_driven</td>.*?</tr>", page, flags=re.S)
    assert row is not None and "all 12 bound-limited: not constrained by the data" in row.group(0)
    assert "−500 … 500" not in page
    assert "bound-limited: reaches the physical range [−500, 500], not measured" in page
    # a measured interval stays an interval
    assert "−0.498 … −0.496" in page
    # the report's own flag (added by a later version) is honoured too
    marked = copy.deepcopy(report)
    marked["effects"][0]["bound_limited"] = ["dt_squared_s2"]
    assert page.count("not measured") + 1 == report_html(marked).count("not measured")


def test_couplings_name_their_axes_and_long_names_wrap(report: dict[str, Any]) -> None:
    page = report_html(report)
    assert "sensor x axis per A·m² of the y torquer [nT/(A·m²)]" in page
    assert "couplings in sensor axes (rows) per body-axis torquer dipole (columns)" in page
    # FAC's long parameter names and values wrap inside fixed-width columns
    assert "table-layout: fixed" in page and "overflow-wrap: anywhere" in page
    assert "<td>east s62 cos mlt</td>" in page


def test_a_none_verdict_reads_as_such(report: dict[str, Any]) -> None:
    none = copy.deepcopy(report)
    none["verdict"] = "none"
    none["verdict_status"] = "none"
    none["verdict_confidence"] = 1.0
    none["separation"] = []
    for e in none["effects"]:
        e["significant"] = False
    none["final"] = {**none["final"], "effects": [], "where": None}
    page = report_html(none)
    seen = _visible(page)
    assert " ".join(seen.ids["verdict"].split()) == "No unmodelled effect found"
    assert "none (none" not in page and "confidence" not in page
    assert 'id="size"' not in page
    steps = " ".join(seen.ids["next-step"].split())
    assert "more data" in steps and "prior calibration" in steps and "different attitude" in steps


def test_keys_added_later_are_shown_not_refused(report: dict[str, Any]) -> None:
    later = copy.deepcopy(report)
    later["gap"] = {"statement": "an unexplained gap of 1.2 nT remains", "rms_nt": 1.2}
    later["something_new"] = {"values": [1, 2, 3]}
    del later["evidence"]  # a report written before the evidence curves
    page = report_html(later)
    seen = _visible(page)
    assert "an unexplained gap of 1.2 nT remains" in " ".join(seen.parts)
    assert "Also in the JSON download: Something new" in page
    assert "No evidence curves in this report" in page


def test_cli_and_service_render_the_same_page(report: dict[str, Any]) -> None:
    """The service's route calls the same function on the cached JSON (tests/api checks the
    route); the CLI writes ``report_html(report)`` of the JSON it writes: a JSON round trip
    changes nothing."""
    assert report_html(json.loads(json.dumps(report))) == report_html(report)


@pytest.mark.browser
@pytest.mark.timeout(180)
def test_first_screen_in_chromium(report: dict[str, Any], tmp_path: Path) -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).parent / "api"))
    from cdp import Browser

    path = tmp_path / "report.html"
    path.write_text(report_html(report, title="orbitcal diagnosis of ISS (README world)"))
    height = 900  # a laptop screen
    with Browser(width=1280, height=height) as browser:
        browser.navigate(path.as_uri())
        browser.wait_for("document.readyState === 'complete'")

        def box(selector: str) -> dict[str, float]:
            rect: dict[str, float] = browser.evaluate(
                f"(() => {{ const r = document.querySelector('{selector}')"
                ".getBoundingClientRect(); return {top: r.top, bottom: r.bottom, "
                "width: r.width}; })()"
            )
            return rect

        for selector in ("#verdict", "#where", "#how-sure", "#next-step", "#json-link"):
            r = box(selector)
            assert r["width"] > 0 and r["bottom"] <= height, (selector, r)
        plots = browser.evaluate(
            "[...document.querySelectorAll('.evidence-plot svg')].map(s => "
            "[s.getBoundingClientRect().bottom, s.getBoundingClientRect().width, "
            "s.querySelectorAll('polyline').length])"
        )
        assert len(plots) == 3
        assert all(width > 300 and lines == 2 for _, width, lines in plots)  # before and after
        assert sum(bottom <= height for bottom, _, _ in plots) >= 2  # two plots on screen
        assert "time_offset" in browser.evaluate("document.getElementById('verdict').innerText")
        shot = browser.screenshot(tmp_path / "report-first-screen.png", full_page=False)
    keep = os.environ.get("ORBITCAL_SCREENSHOT_DIR")
    if keep:
        shutil.copy(shot, Path(keep) / shot.name)
