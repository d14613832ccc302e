"""Reliability suite: a per-class summary of the black-box probes (``probes.py``) at the end."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: Any) -> Iterator[None]:
    """A test that fails marks the probes it recorded as failed (those recorded outside
    ``ServeProcess.run`` too), so that the summary's ``failed`` column counts them."""
    probes = sys.modules.get("probes")
    start = len(probes.RESULTS) if probes is not None else 0
    outcome = yield
    probes = sys.modules.get("probes")
    excinfo = outcome.excinfo  # type: ignore[attr-defined]
    if probes is not None and excinfo is not None:
        for result in probes.RESULTS[start:]:
            if not result.failure:
                result.failure = f"{excinfo[0].__name__}: {excinfo[1]}"[:500] or "failed"


def pytest_terminal_summary(terminalreporter: Any) -> None:
    probes = sys.modules.get("probes")
    if probes is None or not probes.RESULTS:
        return
    rows = probes.summarize(probes.RESULTS)
    tr = terminalreporter
    tr.section("black-box probes (orbitcal serve)")
    tr.write_line(
        f"{'class':<22} {'db':<10} {'probes':>6} {'failed':>6} {'deaths':>6} {'5xx':>4} "
        f"{'peak RSS MiB':>12} {'(+MiB)':>7}  statuses / worst body"
    )
    for row in rows:
        tr.write_line(
            f"{row['class']:<22} {row['database']:<10} {row['probes']:>6} {row['failed']:>6} "
            f"{row['deaths']:>6} {row['status_5xx']:>4} {row['peak_rss_mb']:>12.1f} "
            f"{row['peak_growth_mb']:>+7.1f}  "
            f"{row['statuses']} {row['worst_probe']} ({row['worst_body_bytes']} B)"
        )
    total = len(probes.RESULTS)
    deaths = sum(not r.alive for r in probes.RESULTS)
    errors = sum(r.status >= 500 or r.status < 0 for r in probes.RESULTS)
    tr.write_line(f"{total} probes, {deaths} process deaths, {errors} answers >= 500 or none")
    report = os.environ.get("ORBITCAL_PROBE_REPORT")
    if report:
        Path(report).write_text(
            json.dumps({"summary": rows, "probes": [vars(r) for r in probes.RESULTS]}, indent=1)
        )
