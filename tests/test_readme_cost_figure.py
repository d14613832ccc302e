"""The README's diagnosis-cost figure is the timing page's newest run, never typed by hand."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import diagnose_timing  # noqa: E402

PAGE = """# Diagnose timing

## 2030-01-02 (a session): something, against linear

| pair | ... |

Median ratio: wall 2.50×, cpu 2.75×.

Median ratio this / that: wall 0.912, cpu 0.934.

## 2029-12-31 (an older one)

Median ratio: wall 9.99×, cpu 9.99×.
"""


def test_figure_is_the_newest_section_of_the_page() -> None:
    figure = diagnose_timing.readme_figure(PAGE)
    assert figure.startswith("2.50× `calibrate --method linear` wall (2.75× CPU)")
    assert "(2030-01-02 (a session))" in figure
    assert "0.912× the wall (0.934× the CPU)" in figure
    assert "9.99" not in figure


def test_readme_quotes_the_timing_page() -> None:
    readme = (ROOT / "README.md").read_text()
    page = diagnose_timing.RESULTS.read_text()
    start = readme.index(diagnose_timing.README_BEGIN) + len(diagnose_timing.README_BEGIN)
    quoted = readme[start : readme.index(diagnose_timing.README_END)]
    assert quoted == diagnose_timing.readme_figure(page)
