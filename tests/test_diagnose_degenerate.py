"""Degenerate inputs through the diagnosis's public doors: a typed error that says what to do, or a
report -- never a traceback (CLI) or a bare exception (library; the service maps OrbitcalError to
4xx/503, ``service/app.py``).

The table walked: no sample, one sample, ten samples (too few for held-out blocks), a constant
measured field, a spacecraft frozen in place and attitude (the reference field the same at every
sample: the 12-parameter design is singular), and a prior document without a linear part or with
non-positive widths.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from orbitcal.diagnose import AttributionOptions, DiagnosisOptions, diagnose
from orbitcal.errors import BadInputError, NotEnoughDataError, OrbitcalError
from orbitcal.telemetry import Telemetry

#: Without the crustal and learned models and the split fits: the doors are what is tested.
FAST = DiagnosisOptions(
    crust_model=None, learned=False, attribution=AttributionOptions(split_tests=False)
)


@pytest.fixture(scope="module")
def world() -> tuple[Telemetry, object, str]:
    """Two orbits of Swarm A at 20 s (nadir, no effect): telemetry, orbit, TLE text."""
    from orbitcal.data import real_tles_text
    from orbitcal.orbit import Orbit
    from orbitcal.simulate import NadirLVLH, parse_tles, simulate_world

    swarm_a = [s for s in parse_tles(real_tles_text()) if s.norad_id == 39452]
    tle = max(swarm_a, key=lambda s: s.epoch_utc_s)
    w = simulate_world(
        tle,
        start_utc_s=tle.epoch_utc_s + 3600.0,
        duration_s=2 * 5650.0,
        cadence_s=20.0,
        rng=np.random.default_rng(0),
        attitude=NadirLVLH(),
        effects=[],
    )
    return w.telemetry, Orbit.from_tle(tle.text), tle.text


def _first(tel: Telemetry, n: int) -> Telemetry:
    return dataclasses.replace(
        tel,
        t_utc_s=tel.t_utc_s[:n],
        b_raw_nt=tel.b_raw_nt[:n],
        q_wxyz=None if tel.q_wxyz is None else tel.q_wxyz[:n],
        r_itrs_km=None if tel.r_itrs_km is None else tel.r_itrs_km[:n],
        temperature_c=None,
        mtq_am2=None,
        hk={},
    )


@pytest.mark.parametrize(("n", "says"), [(0, "0 sample"), (1, "1 sample"), (10, "too few")])
def test_too_few_samples_is_not_enough_data(
    world: tuple[Telemetry, object, str], n: int, says: str
) -> None:
    tel, orbit, _ = world
    with pytest.raises(NotEnoughDataError, match=says) as info:
        diagnose(_first(tel, n), orbit=orbit, options=FAST)  # type: ignore[arg-type]
    assert "provide" in str(info.value)  # says what to do
    assert info.value.exit_code == 3 and info.value.http_status < 500


def _frozen(tel: Telemetry, orbit: object) -> Telemetry:
    """Every sample at the first one's position and attitude: one reference vector."""
    from orbitcal.truth import truth_for_telemetry

    first = _first(tel, 1)
    r0 = np.asarray(truth_for_telemetry(first, orbit=orbit).r_itrs_km)[0]  # type: ignore[arg-type]
    n = tel.t_utc_s.size
    assert tel.q_wxyz is not None
    return dataclasses.replace(
        tel, r_itrs_km=np.tile(r0, (n, 1)), q_wxyz=np.tile(tel.q_wxyz[0], (n, 1))
    )


@pytest.mark.parametrize("case", ["constant field", "frozen spacecraft"])
def test_degenerate_fields_give_a_report_or_a_typed_error(
    world: tuple[Telemetry, object, str], case: str
) -> None:
    tel, orbit, _ = world
    if case == "constant field":
        bad = dataclasses.replace(tel, b_raw_nt=np.tile(tel.b_raw_nt[:1], (tel.t_utc_s.size, 1)))
    else:
        bad = _frozen(tel, orbit)
    try:
        diagnosis = diagnose(bad, orbit=orbit, options=FAST)  # type: ignore[arg-type]
    except OrbitcalError as exc:  # a typed error is an answer too
        assert exc.http_status < 500 or exc.http_status == 503
        return
    report = diagnosis.report.to_json()
    json.dumps(report, allow_nan=False)
    assert report["verdict"] in {"none", *(e["name"] for e in report["effects"])}


def test_prior_documents_without_a_linear_part_are_bad_input(
    world: tuple[Telemetry, object, str],
) -> None:
    tel, orbit, _ = world
    with pytest.raises(BadInputError, match="linear"):
        diagnose(tel, orbit=orbit, options=FAST, prior={"method": "lmbp"})  # type: ignore[arg-type]
    doc = {"version": 1, "method": "linear", "linear": {"M": np.eye(3).tolist(), "o": [0, 0, 0]}}
    zero = dataclasses.replace(FAST, prior_sigma_offset_nt=0.0)
    with pytest.raises(BadInputError, match="positive"):
        diagnose(tel, orbit=orbit, options=zero, prior=doc)  # type: ignore[arg-type]


def test_cli_answers_ten_samples_with_one_line_and_exit_3(
    world: tuple[Telemetry, object, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from orbitcal.cli import main
    from orbitcal.telemetry import write_telemetry

    tel, _, tle_text = world
    write_telemetry(tmp_path / "ten.csv", _first(tel, 10))
    (tmp_path / "sat.tle").write_text(tle_text + "\n")
    out = tmp_path / "report.json"
    args = ["diagnose", str(tmp_path / "ten.csv"), "--tle", str(tmp_path / "sat.tle")]
    code = main([*args, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 3, err
    assert err.count("\n") == 1 and "too few samples" in err and "Traceback" not in err
    assert not out.exists()
