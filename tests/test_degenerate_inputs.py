"""Degenerate inputs at every public door (issue 23 item 4, issue 24 item 6): the library's entry
points and the CLI's commands with an empty table, one sample, ten samples, a constant field (a
stuck sensor) and NaN-free but singular readings (a dead axis). Each either works or raises an
:class:`~orbitcal.errors.OrbitcalError` (the CLI: a non-zero exit with one line on stderr); none
escapes as a built-in exception or a traceback. The HTTP half is
``tests/api/test_service_degenerate.py``.

The table (entry × input → outcome) is printed at the end (``pytest -s``).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import orbitcal
from orbitcal.cli import main
from orbitcal.errors import OrbitcalError
from orbitcal.orbit import Orbit
from orbitcal.pipeline import RetrainOptions, retrain
from orbitcal.reproduce.onorbit import OrbitWorld, orbit_world, write_tle
from orbitcal.telemetry import Telemetry, write_telemetry

INPUTS = ("empty", "one sample", "ten samples", "constant field", "singular (dead axis)")
TABLE: list[tuple[str, str, str]] = []


@pytest.fixture(scope="module")
def world() -> OrbitWorld:
    return orbit_world(attitude="nadir", n_samples=400, rng=np.random.default_rng(3))


def degenerate(tel: Telemetry, name: str) -> Telemetry:
    b = tel.b_raw_nt
    return {
        "empty": lambda: tel.select(np.arange(0)),
        "one sample": lambda: tel.select([0]),
        "ten samples": lambda: tel.select(np.arange(10)),
        "constant field": lambda: dataclasses.replace(
            tel, b_raw_nt=np.repeat(b[:1], len(tel), axis=0)
        ),
        "singular (dead axis)": lambda: dataclasses.replace(
            tel, b_raw_nt=np.c_[b[:, :2], np.full(len(tel), 1234.5)]
        ),
    }[name]()


@pytest.fixture(scope="module", autouse=True)
def _print_table() -> Iterator[None]:
    yield
    if TABLE:
        width = max(len(e) for e, _, _ in TABLE)
        print(f"\n{'entry':{width}s}  {'input':22s} outcome")
        for entry, case, outcome in TABLE:
            print(f"{entry:{width}s}  {case:22s} {outcome}")


def _outcome(entry: str, case: str, call: Callable[[], Any]) -> str:
    try:
        result = call()
        promotion = getattr(result, "promotion", None)
        outcome = "ok" if promotion is None else f"ok, not promoted: rule {promotion.rule}"
        if promotion is not None:  # a retraining on data that cannot determine a calibration
            assert not promotion.promote and promotion.rule == "undetermined", promotion
    except OrbitcalError as exc:
        outcome = f"{type(exc).__name__}: {' '.join(str(exc).split())[:90]}"
    except Exception as exc:  # the defect this test exists for
        TABLE.append((entry, case, f"ESCAPED {type(exc).__name__}: {exc}"[:120]))
        raise AssertionError(f"{entry} on {case}: {type(exc).__name__} escaped: {exc}") from exc
    TABLE.append((entry, case, outcome))
    return outcome


LIBRARY: dict[str, Callable[[Telemetry, Orbit, dict[str, Any]], Any]] = {
    "read_table": lambda t, o, d: orbitcal.read_table(t.to_frame()),
    "reference_field": lambda t, o, d: orbitcal.reference_field(t, orbit=o),
    "calibrate_table linear": lambda t, o, d: orbitcal.calibrate_table(t, orbit=o, method="linear"),
    "calibrate_table lmbp-hk": lambda t, o, d: orbitcal.calibrate_table(t, orbit=o, max_epochs=20),
    "calibrate_table twostep": lambda t, o, d: orbitcal.calibrate_table(
        t, orbit=o, method="twostep"
    ),
    "apply_calibration": lambda t, o, d: orbitcal.apply_calibration(d, t),
    "pipeline.retrain": lambda t, o, d: retrain(
        t, orbit=o, champion=None, options=RetrainOptions("linear"), rng=np.random.default_rng(0)
    ),
    "diagnose_table": lambda t, o, d: orbitcal.diagnose_table(t, orbit=o),
}


@pytest.mark.parametrize("case", INPUTS)
@pytest.mark.parametrize("entry", list(LIBRARY))
def test_library_entry_points_raise_only_orbitcal_errors(
    world: OrbitWorld, entry: str, case: str
) -> None:
    orbit = Orbit.from_tle(world.tle)
    document = orbitcal.calibrate_table(world.telemetry, orbit=orbit, method="linear").document
    tel = degenerate(world.telemetry, case)
    _outcome(entry, case, lambda: LIBRARY[entry](tel, orbit, document))


@pytest.fixture(scope="module")
def files(world: OrbitWorld, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("degenerate")
    out = {"tle": write_tle(d / "sat.tle", world.tle)}
    for case in INPUTS:
        path = d / f"{case.split()[0]}.csv"
        write_telemetry(path, degenerate(world.telemetry, case))
        out[case] = path
    cal = d / "cal.json"
    good = orbitcal.calibrate_table(
        world.telemetry, orbit=Orbit.from_tle(world.tle), method="linear"
    )
    cal.write_text(json.dumps(good.document))
    out["cal"] = cal
    return out


def _cli(files: dict[str, Path], tmp: Path, command: str, case: str) -> list[str]:
    tel, tle = str(files[case]), str(files["tle"])
    method = ["--method", "linear"]
    return {
        "calibrate": ["calibrate", tel, "--tle", tle, *method, "--out", str(tmp / "c.json")],
        "apply": ["apply", str(files["cal"]), tel, "--out", str(tmp / "a.csv")],
        "truth": ["truth", tel, "--tle", tle, "--out", str(tmp / "t.csv")],
        "diagnose": ["diagnose", tel, "--tle", tle, "--out", str(tmp / "d.json")],
    }[command]  # fmt: skip


@pytest.mark.parametrize("case", INPUTS)
@pytest.mark.parametrize("command", ["calibrate", "apply", "truth", "diagnose"])
def test_cli_commands_exit_with_one_line_never_a_traceback(
    files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    case: str,
) -> None:
    argv = _cli(files, tmp_path, command, case)
    entry = f"orbitcal {command}"
    try:
        code = main(argv)
    except Exception as exc:  # main re-raises what it cannot name: a traceback for the user
        TABLE.append((entry, case, f"TRACEBACK {type(exc).__name__}: {exc}"[:120]))
        raise AssertionError(f"{entry} on {case}: traceback {type(exc).__name__}: {exc}") from exc
    err = capsys.readouterr().err.strip()
    if code == 0:
        TABLE.append((entry, case, "exit 0"))
        return
    lines = [ln for ln in err.splitlines() if "warning:" not in ln]
    TABLE.append((entry, case, f"exit {code}: {' '.join(lines)[:90]}"))
    assert len(lines) == 1 and lines[0].startswith(f"orbitcal {command}: "), err
    assert "Traceback" not in err
