"""Inputs that parse but are not physical, at every library and CLI door (issue 44 item 9).

A nadir Swarm-A world (:func:`orbitcal.reproduce.onorbit.orbit_world`, seed 3) in nT, and the
same table in Tesla, Gauss and µT, with two axes swapped, with one axis stuck, and with the
elements of another spacecraft (the ISS set nearest in epoch). Through ``calibrate_table``,
``pipeline.retrain`` (the promotion the service runs), ``apply_calibration`` and ``orbitcal
calibrate`` / ``orbitcal apply``: each implausible case is refused or warned about in words that
name it, and **none is promoted**. The Yamcs push refuses an implausible document whatever
promoted it. The HTTP half is ``tests/api/test_service_plausibility.py``; the table printed here
(``pytest -s``) is in ``benchmarks/results/degenerate_inputs.md``.
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from plausibility_cases import CASES, SAYS, UNIT_SCALE, case_field

import orbitcal
from orbitcal.cli import main
from orbitcal.data import real_tles_text
from orbitcal.errors import OrbitcalError
from orbitcal.orbit import Orbit
from orbitcal.pipeline import RetrainOptions, retrain
from orbitcal.plausibility import (
    GAIN_BOUNDS,
    MAX_HOLDOUT_RMS_NT,
    calibration_problem,
    dipole_field_bounds_nt,
    document_problem,
    field_scale_problem,
)
from orbitcal.reproduce.onorbit import OrbitWorld, orbit_world, write_tle
from orbitcal.telemetry import Telemetry, write_telemetry

TABLE: list[tuple[str, str, str]] = []


@pytest.fixture(scope="module")
def world() -> OrbitWorld:
    return orbit_world(attitude="nadir", n_samples=1500, rng=np.random.default_rng(3))


def _case(world: OrbitWorld, name: str) -> tuple[Telemetry, str]:
    """The table and the TLE text of case ``name``."""
    tel = world.telemetry
    if name == "wrong spacecraft":
        iss = orbitcal.load_orbit(real_tles_text(), norad_id=25544, near_utc_s=tel.t_utc_s[0])
        return tel, "\n".join(iss.source[-2:])
    b = case_field(tel.b_raw_nt, name)
    if b is tel.b_raw_nt:
        return tel, world.tle
    return dataclasses.replace(tel, b_raw_nt=b), world.tle


@pytest.fixture(scope="module", autouse=True)
def _print_table() -> Iterator[None]:
    yield
    if TABLE:
        print(f"\n{'entry':28s} {'input':18s} outcome")
        for entry, case, outcome in TABLE:
            print(f"{entry:28s} {case:18s} {outcome}")


def _outcome(entry: str, case: str, call: Callable[[], Any]) -> tuple[str, Any]:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            result = call()
        except OrbitcalError as exc:
            text = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            TABLE.append((entry, case, text[:200]))
            return text, None
    noted = [str(w.message) for w in seen if "implausible" in str(w.message)]
    promotion = getattr(result, "promotion", None)
    if promotion is not None:
        text = "promoted" if promotion.promote else f"not promoted ({promotion.rule})"
        text += f": {promotion.reason}"
    else:
        text = "ok" + (f", warning: {noted[0]}" if noted else "")
    TABLE.append((entry, case, " ".join(text.split())[:200]))
    return text, result


def _orbit(tle: str) -> Orbit:
    return Orbit.from_tle(tle)


@pytest.mark.parametrize("case", CASES)
def test_library_names_each_implausible_input_and_promotes_none(
    world: OrbitWorld, case: str
) -> None:
    tel, tle = _case(world, case)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stale ISS elements: beside the point here
        orbit = _orbit(tle)
    text, _run = _outcome(
        "calibrate_table linear",
        case,
        lambda: orbitcal.calibrate_table(tel, orbit=orbit, method="linear"),
    )
    said, retrained = _outcome(
        "pipeline.retrain (promotion)",
        case,
        lambda: retrain(
            tel,
            orbit=orbit,
            champion=None,
            options=RetrainOptions("linear"),
            rng=np.random.default_rng(0),
        ),
    )
    good = orbitcal.calibrate_table(
        world.telemetry, orbit=_orbit(world.tle), method="linear"
    ).document
    applied, _ = _outcome("apply_calibration", case, lambda: orbitcal.apply_calibration(good, tel))
    if case == "nT (control)":
        assert text == "ok" and retrained is not None and retrained.promotion.promote, said
        return
    assert SAYS[case] in text, text
    assert retrained is None or not retrained.promotion.promote, said
    assert SAYS[case] in said or retrained is None, said
    if case in ("Tesla", "Gauss"):  # no orbit at apply: the surface-to-GEO range holds these
        assert SAYS[case] in applied, applied


@pytest.fixture(scope="module")
def files(world: OrbitWorld, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("plausibility")
    out: dict[str, Path] = {}
    for k, case in enumerate(CASES):
        tel, tle = _case(world, case)
        write_telemetry(d / f"case{k}.csv", tel)
        out[case] = d / f"case{k}.csv"
        out[case + " tle"] = write_tle(d / f"case{k}.tle", tle)
    good = orbitcal.calibrate_table(world.telemetry, orbit=_orbit(world.tle), method="linear")
    out["cal"] = d / "cal.json"
    out["cal"].write_text(json.dumps(good.document))
    return out


@pytest.mark.parametrize("case", CASES)
def test_cli_names_each_implausible_input(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    argv = ["calibrate", str(files[case]), "--tle", str(files[case + " tle"])]
    argv += ["--method", "linear", "--allow-stale-elements", "--out", str(tmp_path / "c.json")]
    with warnings.catch_warnings(record=True) as seen:  # pytest records what stderr would show
        warnings.simplefilter("always")
        code = main(argv)
    shown = [
        f"orbitcal calibrate: warning: {w.message}" for w in seen if "implaus" in str(w.message)
    ]
    err = " ".join(" ".join([capsys.readouterr().err, *shown]).split())
    TABLE.append(("orbitcal calibrate", case, f"exit {code}: {err}"[:200]))
    code_apply = main(["apply", str(files["cal"]), str(files[case]), "--out", str(tmp_path / "a")])
    err_apply = " ".join(capsys.readouterr().err.split())
    TABLE.append(("orbitcal apply", case, f"exit {code_apply}: {err_apply}"[:200]))
    if case == "nT (control)":
        assert code == 0 and "implausible" not in err, err
        return
    assert SAYS[case] in err, err
    assert code != 0 or "will not be promoted" in err, err


def test_the_bounds_and_messages_of_each_class() -> None:
    lo, hi = dipole_field_bounds_nt(6371.2 + 450)
    assert 14_000 < lo < 15_000 and 55_000 < hi < 56_000  # (R/r)^3 = 0.815 at 450 km
    b = np.tile([20_000.0, 5_000.0, 30_000.0], (50, 1))
    assert field_scale_problem(b, r_km=6371.2 + 450) is None
    for unit, factor in UNIT_SCALE.items():
        assert f"looks like {unit}" in str(field_scale_problem(b * factor, r_km=6821.2))
    assert "gains" in str(calibration_problem(np.eye(3) * 1e9, 1.0))
    assert "gains" in str(calibration_problem(np.diag([1.0, 1.0, GAIN_BOUNDS[0] / 2]), 1.0))
    assert "held-out" in str(calibration_problem(np.eye(3), MAX_HOLDOUT_RMS_NT * 1.5))
    assert calibration_problem(np.eye(3) * 1.3, 50.0) is None
    assert "nothing" not in str(document_problem({"linear": {"M": np.eye(3).tolist()}}))
    assert document_problem({"linear": {"M": np.eye(3).tolist()}, "metrics": {}}) is None


def test_an_implausible_document_is_never_pushed() -> None:
    from service.settings import Settings
    from service.yamcs_hook import push_after_promotion

    settings = Settings(yamcs_push_url="http://127.0.0.1:9", scheduler=False)
    doc = {"version": 3, "linear": {"M": (np.eye(3) * 1e9).tolist(), "o": [0, 0, 0]}}
    doc["metrics"] = {"holdout_rms_nt": 0.0}
    report = push_after_promotion(settings, doc, transport=object())  # no transport is used
    assert report is not None and report["error"].startswith("not pushed: implausible"), report
