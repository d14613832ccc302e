"""The README's notebook block runs from the folder that holds the clone (issue 47).

A clone is a folder named ``orbitcal``; Python run from its parent (where a notebook is often
started) saw that folder as a namespace package before the installed one when ``pip install -e .``
had installed an import hook (``module 'orbitcal' has no attribute 'read_table'``). The project's
``package-dir`` makes the editable install a plain path entry instead; this test builds the
editable wheel of a copy of the clone named ``orbitcal`` (setuptools' own build hook, offline),
takes the path its ``.pth`` adds, and runs the README block, as written but for the world's
folder, from the clone's parent with that path where ``site`` would put it.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _readme_block() -> str:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## From a notebook") :]
    (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)[:1]
    return block


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


@pytest.mark.slow
def test_the_notebook_block_runs_from_the_folder_holding_the_clone(tmp_path: Path) -> None:
    holder = tmp_path / "work"
    clone = holder / "orbitcal"  # the clone's folder, named like the package
    clone.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, clone / name)
    for name in ("orbitcal", "service"):
        shutil.copytree(ROOT / name, clone / name, ignore=shutil.ignore_patterns("__pycache__"))
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    build = f"from setuptools import build_meta; print(build_meta.build_editable({str(wheels)!r}))"
    out = subprocess.run(
        [sys.executable, "-c", build], cwd=clone, env=_env(), capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-2000:]
    (wheel,) = wheels.glob("*.whl")
    with zipfile.ZipFile(wheel) as z:
        (pth,) = [n for n in z.namelist() if n.endswith(".pth")]
        entry = z.read(pth).decode().strip()
    # a path, not an import hook: sys.path's own finder sees the package
    assert not entry.startswith("import"), entry
    assert Path(entry).resolve() == clone.resolve()

    world = tmp_path / "world"
    simulate = [
        sys.executable, "-m", "orbitcal", "simulate",
        "--tle", str(ROOT / "tests" / "authorities" / "swarm_iss_real_tles.tle"),
        "--norad", "25544", "--start", "2022-08-02T00:00:00Z", "--duration-s", "21600",
        "--cadence-s", "10", "--attitude", "tumbling", "--effect", "time_offset", "--seed", "4",
        "--out", str(world),
    ]  # fmt: skip
    subprocess.run(simulate, check=True, capture_output=True, cwd=tmp_path, env={
        **_env(), "PYTHONPATH": str(ROOT)})  # fmt: skip

    block = _readme_block().replace("/tmp/world", str(world))
    # site.addsitedir appends a .pth's path to sys.path after the script's folder ('' here)
    program = (
        f"import sys; sys.path.append({entry!r})\n"
        + block
        + ("\nimport orbitcal\nprint('from', orbitcal.__file__)\n")
    )
    out = subprocess.run(
        [sys.executable, "-c", program], cwd=holder, env=_env(), capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-3000:]
    lines = out.stdout.splitlines()
    assert lines[-2] == "time_offset", out.stdout
    assert lines[-3].startswith("Report(verdict time_offset, time offset dt = −0.")
    # the regular package, not the clone folder as a namespace package: this copy's, or, where
    # the test's own environment has the project installed as a path entry too (CI's editable
    # install, listed before the appended one), the project's
    imported = {
        f"from {clone / 'orbitcal' / '__init__.py'}",
        f"from {ROOT / 'orbitcal' / '__init__.py'}",
    }
    assert lines[-1] in imported, out.stdout
    assert lines[0].startswith("CalibrationRun(linear, spacecraft 'ISS (ZARYA)', 2160 samples")
