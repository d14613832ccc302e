"""Ctrl-C in the command line (issue 44 item 10): one line on stderr, exit 130, no traceback;
a long command keeps what it finished.

Real ``SIGINT``s to real ``orbitcal`` processes: ``bench diagnose`` is interrupted once its first
world is on disk (the test polls for that line, never sleeps a guessed time); the import cases
raise the signal from inside an import, as a Ctrl-C during start-up does, including the
``ImportError: initialization failed`` an extension module turns it into.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orbitcal.cli import EXIT_INTERRUPTED

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _one_line(stderr: str, command: str, progress: str = "\0") -> str:
    """The one line of stderr besides warnings and the final render of a progress bar (lines
    starting with ``progress``: rich prints its bar once more when it stops, off a terminal)."""
    lines = [
        ln
        for ln in stderr.splitlines()
        if ln.strip() and "warning:" not in ln and not ln.startswith(progress)
    ]
    assert len(lines) == 1, stderr[-3000:]
    assert "Traceback" not in stderr
    assert lines[0].startswith(f"orbitcal {command}: interrupted (Ctrl-C)"), lines
    return lines[0]


@pytest.mark.slow
def test_bench_diagnose_stops_on_sigint_and_keeps_the_finished_worlds(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    proc = subprocess.Popen(
        [sys.executable, "-m", "orbitcal", "bench", "diagnose", "--cases", "40", "--orbits", "1",
         "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, cwd=tmp_path,
    )  # fmt: skip
    partial = out / "diagnose_partial.ndjson"
    deadline = time.monotonic() + 900  # a guard against a hang, not a measurement
    while not (partial.exists() and partial.read_text().count("\n") >= 1):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no world finished"
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == EXIT_INTERRUPTED, err[-3000:]
    line = _one_line(err, "bench", progress="diagnose ")
    assert f"saved to {partial}" in line
    worlds = [json.loads(ln) for ln in partial.read_text().splitlines()]
    assert 1 <= len(worlds) < 40 and all("correct" in w for w in worlds)
    assert f"{len(worlds)} finished worlds" in line


_IMPORT_HOOK = r"""
import builtins, signal, sys
from orbitcal.cli import main
real = builtins.__import__
mode = sys.argv[1]

def hooked(name, *args, **kwargs):
    if name == "orbitcal.truth" or name.startswith("orbitcal.truth."):
        builtins.__import__ = real
        if mode == "keyboardinterrupt":
            signal.raise_signal(signal.SIGINT)  # the handler raises KeyboardInterrupt here
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:  # what a C extension's init does with it
            raise ImportError("initialization failed") from None
    return real(name, *args, **kwargs)

builtins.__import__ = hooked
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("mode", ["keyboardinterrupt", "importerror"])
def test_sigint_during_a_command_s_imports_is_one_line_and_130(tmp_path: Path, mode: str) -> None:
    tel = tmp_path / "t.csv"
    tel.write_text("time,b_x,b_y,b_z\n2024-01-01T00:00:00Z,1,2,3\n")
    argv = ["truth", str(tel), "--tle", str(tmp_path / "x.tle"), "--out", str(tmp_path / "o.csv")]
    proc = subprocess.run(
        [sys.executable, "-c", _IMPORT_HOOK, mode, *argv],
        capture_output=True, text=True, env=ENV, timeout=300,
    )  # fmt: skip
    assert proc.returncode == EXIT_INTERRUPTED, proc.stderr[-3000:]
    assert "nothing saved" in _one_line(proc.stderr, "truth")


def test_an_import_error_without_sigint_is_still_a_bug(tmp_path: Path) -> None:
    """Only an ImportError that follows a SIGINT is read as the interrupt."""
    code = (
        "import sys; from orbitcal.cli import main; sys.modules['orbitcal.truth'] = None; "
        "sys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, "truth", "x.csv", "--out", "o.csv"],
        capture_output=True, text=True, env=ENV, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode not in (0, EXIT_INTERRUPTED) and "ModuleNotFoundError" in proc.stderr
