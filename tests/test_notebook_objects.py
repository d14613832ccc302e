"""The notebook objects: one-line reprs, to_frame() / to_xarray(), a DataFrame indexed by time,
and a calibration document that names its spacecraft."""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest

import orbitcal
from orbitcal.data import real_tles_text
from orbitcal.simulate import Tumbling, simulate_world
from orbitcal.telemetry import TelemetryError

START_UTC_S = 1_659_398_400.0  # 2022-08-02T00:00:00Z


@pytest.fixture(scope="module")
def world() -> tuple[orbitcal.Telemetry, orbitcal.Orbit]:
    orbit = orbitcal.load_orbit(real_tles_text(), norad_id=39452, near_utc_s=START_UTC_S)
    w = simulate_world(
        orbit,
        start_utc_s=START_UTC_S,
        duration_s=3 * 3600.0,
        cadence_s=20.0,
        rng=np.random.default_rng(1),
        attitude=Tumbling(),
        seed=1,
    )
    return w.telemetry, orbit


def test_reprs_are_one_short_line(world: tuple[orbitcal.Telemetry, orbitcal.Orbit]) -> None:
    tel, orbit = world
    truth = orbitcal.reference_field(tel, orbit=orbit)
    run = orbitcal.calibrate_table(tel, orbit=orbit, method="linear")
    span = "540 samples, 2022-08-02T00:00:00Z … 2022-08-02T02:59:40Z"
    assert repr(tel) == f"Telemetry({span}; columns b, q, temperature, mtq, hk_sa_current_a)"
    assert repr(truth) == f"Truth(IGRF-14, {span}; frames body, itrs, nec; positions from sgp4)"
    text = repr(run)
    assert text.startswith(f"CalibrationRun(linear, spacecraft 'SWARM A', {span}; 405 fitted, ")
    assert "135 held out; held-out RMS " in text and text.endswith(" nT)")
    for shown in (repr(tel), repr(truth), text):
        assert "\n" not in shown and len(shown) < 200 and "array(" not in shown


def test_frames_and_datasets(world: tuple[orbitcal.Telemetry, orbitcal.Orbit]) -> None:
    tel, orbit = world
    truth = orbitcal.reference_field(tel, orbit=orbit)
    run = orbitcal.calibrate_table(tel, orbit=orbit, method="linear")
    tf = truth.to_frame()
    assert isinstance(tf.index, pd.DatetimeIndex) and str(tf.index.tz) == "UTC"
    assert tf.index[0] == pd.Timestamp("2022-08-02T00:00:00Z")
    np.testing.assert_array_equal(tf["b_nec_c_nt"].to_numpy(), truth.b_nec_nt[:, 2])
    rf = run.to_frame()
    assert int(rf["held_out"].sum()) == int(run.holdout.sum())
    residual = rf[["residual_x_nt", "residual_y_nt", "residual_z_nt"]].to_numpy()[rf["held_out"]]
    rms = float(np.sqrt(np.mean(residual**2)))
    assert rms == pytest.approx(run.document["metrics"]["holdout_rms_nt"], rel=1e-3)
    for obj, column in ((tel, "b_x"), (truth, "b_body_x_nt"), (run, "b_cal_x_nt")):
        ds = obj.to_xarray()
        assert ds.sizes["time"] == len(tel) and column in ds
        assert ds.attrs["time_scale"] == "UTC"
        assert ds["time"].values[0] == np.datetime64("2022-08-02T00:00:00")


def test_to_xarray_without_xarray_says_how_to_install(
    world: tuple[orbitcal.Telemetry, orbitcal.Orbit], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "xarray", None)  # as if not installed
    with pytest.raises(ImportError, match="pip install xarray"):
        world[0].to_xarray()


def test_a_frame_indexed_by_time_is_accepted_or_refused_with_a_hint(
    world: tuple[orbitcal.Telemetry, orbitcal.Orbit],
) -> None:
    tel = world[0]
    indexed = tel.to_frame()  # indexed by UTC time
    same = orbitcal.read_table(indexed)
    np.testing.assert_allclose(same.t_utc_s, tel.t_utc_s, atol=1e-6)
    np.testing.assert_array_equal(same.b_raw_nt, tel.b_raw_nt)
    with pytest.raises(TelemetryError, match=r"no time zone: localize it"):
        orbitcal.read_table(indexed.tz_localize(None))
    with pytest.raises(TelemetryError, match=r"missing column 'time'.*DatetimeIndex"):
        orbitcal.read_table(indexed.reset_index(drop=True))


def test_the_document_names_its_spacecraft(
    world: tuple[orbitcal.Telemetry, orbitcal.Orbit],
) -> None:
    tel, orbit = world
    assert orbitcal.calibrate_table(tel, orbit=orbit, method="linear").document["spacecraft"] == (
        "SWARM A"
    )
    run = orbitcal.calibrate_table(tel, orbit=orbit, method="linear", spacecraft="swarm-a")
    assert run.document["spacecraft"] == "swarm-a"


def test_orbit_repr_names_the_spacecraft_not_the_sgp4_record(
    world: tuple[orbitcal.Telemetry, orbitcal.Orbit],
) -> None:
    orbit = world[1]
    text = repr(orbit)
    assert (
        text.startswith("Orbit('SWARM A', NORAD 39452, epoch 2022-08-0") and "Z, from a TLE" in text
    )
    assert "Satrec" not in text and "0x" not in text and len(text) < 100


def test_the_report_is_typed_short_and_reads_as_a_mapping() -> None:
    """Issue 47: diagnose_table's report (here the committed report of the README's world)."""
    import json
    from collections.abc import Mapping
    from pathlib import Path

    from orbitcal.diagnose import Report

    doc = json.loads(
        (Path(__file__).parent / "fixtures" / "diagnosis_report_time_offset.json").read_text()
    )
    report = Report.from_json(doc)
    assert repr(report) == (
        "Report(verdict time_offset, time offset dt = −0.497 s; held-out RMS 16.0 → 2.08 nT; "
        "11 candidates)"
    )
    assert isinstance(report, Mapping) and report["verdict"] == "time_offset"
    assert set(report) == set(doc) and len(report) == len(doc) and report.to_json() == doc
    report["baseline"]["holdout_rms_nt"] = 0.0  # a copy: the report does not change
    assert report["baseline"]["holdout_rms_nt"] == doc["baseline"]["holdout_rms_nt"]
    effects = report.to_frame()
    assert effects.index.name == "effect" and list(effects.index) == [
        e["name"] for e in doc["effects"]
    ]
    assert effects.loc["time_offset", "holdout_rms_after_nt"] == doc["final"]["holdout_rms_nt"]
    by_time = report.to_frame("time")
    assert isinstance(by_time.index, pd.DatetimeIndex) and str(by_time.index.tz) == "UTC"
    assert by_time.index[0] > pd.Timestamp(doc["data"]["start"])
    assert by_time.index[-1] < pd.Timestamp(doc["data"]["end"])
    assert by_time["held_out"].iloc[-1] and not by_time["held_out"].iloc[0]
    with pytest.raises(ValueError, match="'effects' or 'time'"):
        report.to_frame("samples")
    html = report._repr_html_()
    assert html.startswith('<table class="orbitcal-report">') and len(html) < 3000
    assert "add −0.497 s to the magnetometer time tags" in html


def test_a_diagnosis_shows_its_report_in_one_line(
    world: tuple[orbitcal.Telemetry, orbitcal.Orbit],
) -> None:
    from orbitcal.diagnose import DiagnosisOptions, diagnose

    tel, orbit = world
    diagnosis = diagnose(tel, orbit=orbit, options=DiagnosisOptions(learned=False))
    text = repr(diagnosis)
    assert text.startswith("Diagnosis(Report(verdict ") and text.endswith(" on 540 samples)")
    assert "\n" not in text and len(text) < 250 and "array(" not in text
    assert diagnosis._repr_html_() == diagnosis.report._repr_html_()
    report = orbitcal.diagnose_table(tel, orbit=orbit)
    assert repr(report).startswith("Report(verdict ") and len(repr(report)) < 200
