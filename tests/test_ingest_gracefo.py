"""``orbitcal ingest gracefo`` on the real GRACE-FO C Level-1B files of 2023-06-01.

The files are the first 100 records of each RL04 ASCII product (``tests/authorities/gracefo/``,
provenance in its README). Figures checked here were measured independently of the project
(ppigrf IGRF-14 + Skyfield, ``/tests/authorities/gracefo/README.md``) and re-measured through it.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from orbitcal.attitude import quat_conjugate
from orbitcal.cli import main
from orbitcal.field import get_field
from orbitcal.ingest import GraceFOOptions, IngestError, ingest_gracefo
from orbitcal.ingest.l1b_ascii import END_OF_HEADER
from orbitcal.telemetry import Telemetry, read_telemetry
from orbitcal.truth import truth_for_telemetry

DATA = Path(__file__).parent / "authorities" / "gracefo"
PRODUCTS = ("MAG1B", "GNV1B", "SCA1B", "IHK1B")


def _file(product: str) -> Path:
    return DATA / f"{product}_2023-06-01_C_04.txt"


@pytest.fixture(scope="module")
def table() -> Telemetry:
    t = ingest_gracefo(DATA).telemetry
    assert t is not None
    return t


def _residual(t: Telemetry) -> np.ndarray:
    truth = truth_for_telemetry(t, orbit=None, attitude_frame="GCRS", field=get_field("IGRF-14"))
    assert truth.b_body_nt is not None
    return np.asarray(t.b_raw_nt - truth.b_body_nt)


def test_the_table_first_rows(table: Telemetry) -> None:
    assert len(table) == 100  # every MAG1B record lies inside GNV1B's and SCA1B's spans
    df = table.to_table_frame()
    # 738849600 s + 83329 µs past 2000-01-01 12:00 GPS = 2023-06-01T00:00:00.083329 GPS = -18 s UTC
    assert df["time"].iloc[0] == "2023-05-31T23:59:42.083329Z"
    assert df["time"].iloc[1] == "2023-05-31T23:59:42.583329Z"
    # MfvX/Y/Z_RAW µT -> nT, unchanged otherwise (SRF)
    np.testing.assert_allclose(
        table.b_raw_nt[0], [12328.33957672119, 7117.527008056641, -31842.39959716797], rtol=1e-15
    )
    # position: GNV1B metres -> km, Hermite between the records of 600 s and 601 s (0.083 s in)
    r0 = np.array([562516.6928322315, -2051148.109060925, -6546817.760876593]) / 1e3
    v0 = np.array([-1636.58495865621, 7025.557923232562, -2348.304620900529]) / 1e3
    np.testing.assert_allclose(table.r_itrs_km[0], r0 + v0 * 0.083329, atol=1e-5)  # 1 cm
    # attitude: SCA1B scalar first carried over (same convention), slerped 0.083 s in
    q600 = np.array(
        [0.07816222822585139, 0.1642723922577685, -0.004109730449778668, 0.9833048140804912]
    )
    q601 = np.array(
        [0.07816435498782409, 0.1637291119203296, -0.004066848850920528, 0.9833954303161931]
    )
    np.testing.assert_allclose(table.q_wxyz[0], q600 + 0.083329 * (q601 - q600), atol=1e-8)
    # six torquer currents as hk_ columns [mA], the regressors of the -hk methods
    assert table.hk["hk_torque1a_ma"][0] == pytest.approx(4.621397018432617)
    assert table.hk["hk_torque2b_ma"][0] == pytest.approx(-2.094727039337158)
    assert table.hk["hk_torque3a_ma"][0] == pytest.approx(1.34342896938324)
    _, names = table.regressors()
    assert [n for n in names if "torque" in n] == sorted(
        f"hk_torque{i}{s}_ma" for i in "123" for s in "ab"
    )


def test_summary_names_what_the_files_hide() -> None:
    s = ingest_gracefo(DATA).summary
    assert s.records == {"MAG1B": 100, "GNV1B": 100, "SCA1B": 100, "IHK1B": 100}
    assert s.rows == 100 and not s.dropped
    assert any("declared in nanoseconds but holds microseconds" in n for n in s.notes)
    assert any("100 of the 172800 records" in n for n in s.notes)
    # the fluxgate value repeats in pairs: a 1 Hz field written at 2 Hz (49 repeats in 100)
    assert s.flags["MAG1B"]["field equal to the previous record's (kept)"] == 49
    # IHK1B temperatures (60 s cadence) start 29 s into these 49.5 s: none covers the span
    assert not [c for c in s.columns if c.startswith("hk_ihk1b")]


def test_truth_in_the_sensor_frame_against_the_measured_residual(table: Telemetry) -> None:
    d = _residual(table)
    # the platform magnetometer's offset and the scatter around it (time_frac in microseconds)
    np.testing.assert_allclose(d.mean(axis=0), [-529.5, 16.1, 249.8], atol=1.0)
    np.testing.assert_allclose(d.std(axis=0), [6.6, 6.4, 9.4], atol=0.5)
    # the other quaternion convention leaves thousands of nT
    wrong = _residual(replace(table, q_wxyz=quat_conjugate(table.q_wxyz)))
    assert np.abs(wrong.mean(axis=0)).max() > 1000.0


def test_reading_time_frac_as_declared_reproduces_the_independent_figures() -> None:
    # The independent measurement took time_frac in nanoseconds, as the header says:
    # [-534, 19, 238] nT, scatter [9.2, 7.2, 17.7]. Half the samples then sit 0.5 s early,
    # which is why its scatter is larger than with microseconds (the unit the values hold).
    t = ingest_gracefo(DATA, options=GraceFOOptions(time_frac_unit="nanoseconds")).telemetry
    assert t is not None
    d = _residual(t)
    np.testing.assert_allclose(d.mean(axis=0), [-534.3, 18.8, 238.3], atol=1.0)
    np.testing.assert_allclose(d.std(axis=0), [9.2, 7.2, 17.7], atol=0.5)


def test_calibrating_49_seconds_is_refused(table: Telemetry, tmp_path: Path) -> None:
    """49 s of real data: a well-conditioned design numerically (1.9e5) that leaves the matrix
    undetermined (standard errors up to ~5); every linear method and the CLI refuse it."""
    from orbitcal.calibrate import UndeterminedFitError
    from orbitcal.errors import NotEnoughDataError
    from orbitcal.pipeline import calibrate

    for method in ("linear", "linear-hk"):
        with pytest.raises(NotEnoughDataError, match="determine the calibration matrix only"):
            calibrate(table, method=method, rng=np.random.default_rng(0))
    with pytest.raises(UndeterminedFitError) as info:
        calibrate(table, method="linear", rng=np.random.default_rng(0))
    assert info.value.gain_sd > 1.0  # ±100 % and more: nothing a calibration can rest on


def test_chunked_reading_gives_the_same_table(table: Telemetry) -> None:
    t = ingest_gracefo(DATA, options=GraceFOOptions(chunk_rows=7)).telemetry
    assert t is not None
    np.testing.assert_array_equal(t.t_utc_s, table.t_utc_s)
    np.testing.assert_array_equal(t.b_raw_nt, table.b_raw_nt)
    np.testing.assert_array_equal(t.q_wxyz, table.q_wxyz)


def test_written_table_reads_back(tmp_path: Path, table: Telemetry) -> None:
    for ext in ("csv", "parquet"):
        out = tmp_path / f"gf.{ext}"
        res = ingest_gracefo([_file(p) for p in PRODUCTS], out=out)
        assert res.telemetry is None and res.summary.rows == 100
        back = read_telemetry(out)
        assert not back.rejected
        np.testing.assert_allclose(back.telemetry.t_utc_s, table.t_utc_s, atol=1e-6)
        np.testing.assert_array_equal(back.telemetry.b_raw_nt, table.b_raw_nt)


# --- gaps and spans ----------------------------------------------------------------------------


def _copy_set(tmp_path: Path, products: tuple[str, ...] = PRODUCTS) -> Path:
    d = tmp_path / "l1b"
    d.mkdir()
    for p in products:
        shutil.copy(_file(p), d / _file(p).name)
    return d


def _lines(path: Path) -> tuple[list[str], list[str]]:
    text = path.read_text().splitlines(keepends=True)
    end = next(i for i, line in enumerate(text) if line.startswith(END_OF_HEADER)) + 1
    return text[:end], text[end:]


def test_a_gap_in_the_attitude_drops_the_samples_inside_it(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    sca = d / _file("SCA1B").name
    head, rows = _lines(sca)
    sca.write_text("".join(head + rows[:10] + rows[30:]))  # 20 s without attitude
    res = ingest_gracefo(d)
    assert res.summary.dropped["in SCA1B gap"] == 42  # MAG1B 609.08 … 629.58 s, 2 Hz
    assert res.summary.rows == 58
    assert res.summary.n_gaps == 1 and res.summary.gaps[0].product == "SCA1B"
    assert res.summary.gaps[0].duration_s == pytest.approx(21.0)


def test_samples_past_a_product_span_are_dropped_not_extrapolated(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    gnv = d / _file("GNV1B").name
    head, rows = _lines(gnv)
    gnv.write_text("".join(head + rows[:25]))  # positions end at 624 s
    res = ingest_gracefo(d)
    assert res.summary.dropped["after GNV1B span"] == 52  # MAG1B 624.08 … 649.58
    assert res.telemetry is not None
    assert res.telemetry.t_utc_s.max() <= 738_849_624 + 946_728_000 - 18  # GPS - 18 s


# --- errors: file, line and field named ------------------------------------------------------


def test_a_truncated_file_names_the_line_and_field(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    mag = d / _file("MAG1B").name
    head, rows = _lines(mag)
    cut = rows[41].split()[:9]  # the record ends after torque2A
    mag.write_text("".join(head + rows[:41]) + " ".join(cut) + "\n")
    with pytest.raises(IngestError) as info:
        ingest_gracefo(d)
    line = len(head) + 42
    assert f"MAG1B_2023-06-01_C_04.txt:{line}" in str(info.value)
    assert info.value.field == "torque3A"
    assert "truncated" in str(info.value)


def test_a_missing_product_is_named(tmp_path: Path) -> None:
    d = _copy_set(tmp_path, ("MAG1B", "SCA1B"))
    with pytest.raises(IngestError, match="no GNV1B file for 2023-06-01 C") as info:
        ingest_gracefo(d)
    assert info.value.field == "GNV1B"


def test_a_reordered_layout_is_read_by_the_header_names(tmp_path: Path, table: Telemetry) -> None:
    """Swap two columns in the header *and* the records: the same table comes out."""
    d = _copy_set(tmp_path)
    mag = d / _file("MAG1B").name
    head, rows = _lines(mag)
    text = "".join(head)
    x = text.index("    - MfvX_RAW:")
    z = text.index("    - MfvZ_RAW:")
    end_z = text.index("    - torque1A:")
    x_block = text[x : text.index("    - MfvY_RAW:")]
    z_block = text[z:end_z]
    y_block = text[text.index("    - MfvY_RAW:") : z]
    new_x = x_block.replace("5th column", "7th column")
    new_z = z_block.replace("7th column", "5th column")
    text = text[:x] + new_z + y_block + new_x + text[end_z:]
    swapped = []
    for r in rows:
        f = r.split()
        f[4], f[6] = f[6], f[4]
        swapped.append(" ".join(f) + "\n")
    mag.write_text(text + "".join(swapped))
    t = ingest_gracefo(d).telemetry
    assert t is not None
    np.testing.assert_array_equal(t.b_raw_nt, table.b_raw_nt)


def test_a_foreign_layout_is_refused_not_misread(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    mag = d / _file("MAG1B").name
    mag.write_text(mag.read_text().replace("    - MfvY_RAW:", "    - MfvY_CAL:"))
    with pytest.raises(IngestError, match="declares no column 'MfvY_RAW'") as info:
        ingest_gracefo(d)
    assert info.value.field == "MfvY_RAW"


def test_a_changed_unit_is_refused(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    gnv = d / _file("GNV1B").name
    text = gnv.read_text()
    i = text.index("    - xpos:")
    j = text.index("units: m", i)
    gnv.write_text(text[:j] + "units: km" + text[j + len("units: m") :])
    with pytest.raises(IngestError, match="declares xpos in 'km'"):
        ingest_gracefo(d)


def test_an_extra_field_in_a_record_is_refused(tmp_path: Path) -> None:
    d = _copy_set(tmp_path)
    sca = d / _file("SCA1B").name
    head, rows = _lines(sca)
    rows[5] = rows[5].rstrip("\n") + " 1.0\n"
    sca.write_text("".join(head + rows))
    with pytest.raises(IngestError, match="more fields than the header's 9 columns") as info:
        ingest_gracefo(d)
    assert f"SCA1B_2023-06-01_C_04.txt:{len(head) + 6}" in str(info.value)


def test_the_cli_writes_the_table_and_prints_the_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "gf.parquet"
    summary = tmp_path / "summary.json"
    argv = ["ingest", "gracefo", str(DATA), "--out", str(out), "--summary-json", str(summary)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "GRACE C (GRACE-FO): 100 rows 2023-05-31T23:59:42.083329Z" in printed
    assert read_telemetry(out).telemetry.q_wxyz is not None
    doc = json.loads(summary.read_text())
    assert doc["rows"] == 100 and doc["out"] == str(out)
    assert doc["records"]["MAG1B"] == 100 and doc["first"] == "2023-05-31T23:59:42.083329Z"


def test_the_cli_gives_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = _copy_set(tmp_path, ("MAG1B", "GNV1B"))
    code = main(["ingest", "gracefo", str(d), "--out", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1
    assert err.startswith("orbitcal ingest: ") and "no SCA1B file for 2023-06-01" in err
    assert not (tmp_path / "x.csv").exists()


def test_the_recipe_commands_parse() -> None:
    """Every ``orbitcal`` command of ``docs/real-data.md`` is accepted by the parser as written."""
    import shlex

    from orbitcal.cli import build_parser

    doc = (Path(__file__).parents[1] / "docs" / "real-data.md").read_text()
    commands = [line for line in doc.splitlines() if line.startswith("orbitcal ")]
    assert len(commands) == 4
    parser = build_parser()
    for line in commands:
        args = parser.parse_args(shlex.split(line)[1:])
        assert callable(args.func)


def test_temperatures_covering_the_span_become_columns(tmp_path: Path) -> None:
    """IHK1B moved 60 s earlier: sensors 21-23, 37, 38 (568.98 … 688.98 s) cover MAG1B's span."""
    d = _copy_set(tmp_path)
    ihk = d / _file("IHK1B").name
    head, rows = _lines(ihk)
    moved = [" ".join([str(int(r.split()[0]) - 60), *r.split()[1:]]) + "\n" for r in rows]
    ihk.write_text("".join(head + moved))
    res = ingest_gracefo(d, options=GraceFOOptions(temperature_sensor="21"))
    t = res.telemetry
    assert t is not None and len(t) == 100
    taken = sorted(k for k in t.hk if k.startswith("hk_ihk1b"))
    assert taken == [f"hk_ihk1b_t{s}_degc" for s in ("21", "22", "23", "37", "38")]
    # sensor 21: 24.4216 °C at 568.983 s and 24.4216 °C at 688.983 s; 22: 24.9045 -> 24.9523
    f = (600.083329 - 568.983328) / 120.0
    assert t.hk["hk_ihk1b_t22_degc"][0] == pytest.approx(
        24.90453916280846 + f * (24.9523162387049 - 24.90453916280846)
    )
    assert t.temperature_c is not None
    np.testing.assert_allclose(t.temperature_c, t.hk["hk_ihk1b_t21_degc"])
    assert any("left out: 05, 06" in n for n in res.summary.notes)


def test_thinning_keeps_one_record_per_bin() -> None:
    res = ingest_gracefo(DATA, options=GraceFOOptions(every_s=10.0))
    assert res.summary.rows == 5  # 600.08, 610.08, 620.08, 630.08, 640.08 s
    assert res.summary.dropped["thinned to one record per 10 s"] == 95


def test_the_next_day_s_files_bridge_midnight(tmp_path: Path) -> None:
    """A day whose last MAG1B samples fall after its own last GNV1B/SCA1B record (599.08 s,
    599.58 s after 599 s) keeps them when the next day's files are given, and only then."""
    d = _copy_set(tmp_path, ("MAG1B", "GNV1B", "SCA1B"))
    shifts = {"MAG1B": -50, "GNV1B": -100, "SCA1B": -100}
    for product, shift in shifts.items():
        head, rows = _lines(_file(product))
        moved = [" ".join([str(int(r.split()[0]) + shift), *r.split()[1:]]) + "\n" for r in rows]
        text = "".join(head + moved)
        text = text.replace(
            "start_time_epoch_secs: 738849600.083329", "start_time_epoch_secs: 738849550.083329"
        )
        (d / _file(product).name.replace("2023-06-01", "2023-05-31")).write_text(text)
    both = ingest_gracefo(d)
    assert both.summary.rows == 200 and not both.summary.dropped
    for product in shifts:
        (d / _file(product).name).unlink()
    alone = ingest_gracefo(d)
    assert alone.summary.rows == 98
    assert alone.summary.dropped == {"after GNV1B span": 2}
