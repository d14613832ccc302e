"""docs/tutorial.md runs: every ```python block, in order, in one namespace, in a fresh dir."""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping
from pathlib import Path

import pytest

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", TUTORIAL.read_text(), flags=re.S)


def test_the_tutorial_has_code() -> None:
    assert len(_blocks()) >= 6


def test_the_tutorial_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "tutorial"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library's warnings are not the tutorial's subject
        for k, code in enumerate(_blocks()):
            exec(compile(code, f"{TUTORIAL.name}[block {k + 1}]", "exec"), namespace)
    report = namespace["report"]
    assert isinstance(report, Mapping) and report["verdict"] == "time_offset"
    assert (tmp_path / "cal.json").exists()
