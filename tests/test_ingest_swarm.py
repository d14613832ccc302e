"""``orbitcal ingest swarm`` on real Swarm files, and on an LR_1B-layout CDF of real GRACE-A rows.

* ``authorities/swarm/vires_export_test_data_01.{cdf,csv}``: the same VirES export of Swarm A
  (192 rows, ``B_NEC``) in both formats (viresclient 0.16.0 test data, MIT);
* ``authorities/test_fac_singlesat_swarm.nc4``: Swarm A MAG_LR_1B ``B_NEC``, 1800 s of a storm;
* ``authorities/GRACE_A_MAG_20100101_4rows.csv``: four VirES GRACE-A rows with ``B_FGM``
  (instrument frame), ``B_NEC_raw`` and ``q_NEC_CRF``; written here into a CDF with the variable
  names of the published ``SW_OPER_MAGx_LR_1B`` product (``Timestamp`` CDF_EPOCH, ``Latitude``,
  ``Longitude``, ``Radius``, ``B_VFM``, ``B_NEC``, ``q_NEC_CRF``, ``Flags_B``), since no real LR_1B
  file is in the repository.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orbitcal import frames
from orbitcal.attitude import frame_to_body
from orbitcal.cli import main
from orbitcal.field import get_field
from orbitcal.ingest import IngestError, SwarmOptions, ingest_swarm
from orbitcal.truth import truth_for_telemetry

AUTH = Path(__file__).parent / "authorities"
VIRES = AUTH / "swarm" / "vires_export_test_data_01"


def test_vires_csv_and_cdf_give_the_same_table() -> None:
    a = ingest_swarm(VIRES.with_suffix(".csv")).telemetry
    b = ingest_swarm(VIRES.with_suffix(".cdf")).telemetry
    assert a is not None and b is not None
    assert len(a) == len(b) == 192
    np.testing.assert_allclose(a.t_utc_s, b.t_utc_s, atol=1e-6)
    np.testing.assert_allclose(a.b_raw_nt, b.b_raw_nt, atol=1e-9)
    np.testing.assert_allclose(a.r_itrs_km, b.r_itrs_km, atol=1e-9)
    # first row: 2016-01-01T00:28:00Z, B_NEC {23432.0698;2929.1195;7001.0706}, r = 6828.39061 km
    assert a.to_table_frame()["time"].iloc[0] == "2016-01-01T00:28:00.000000Z"
    np.testing.assert_allclose(a.b_raw_nt[0], [23432.0698, 2929.1195, 7001.0706])
    assert np.linalg.norm(a.r_itrs_km[0]) == pytest.approx(6828.39061, abs=1e-9)


def test_b_nec_body_frame_reproduces_the_measured_storm_residual() -> None:
    """The body frame of a B_NEC table is NEC: the truth in it is the model's N, E, C."""
    t = ingest_swarm(AUTH / "test_fac_singlesat_swarm.nc4").telemetry
    assert t is not None and len(t) == 1800
    truth = truth_for_telemetry(t, orbit=None, attitude_frame="GCRS", field=get_field("IGRF-14"))
    assert truth.b_body_nt is not None
    lat = 90.0 - frames.itrs_to_spherical(t.r_itrs_km)[1]
    low = np.abs(lat) < 40.0
    d = (t.b_raw_nt - truth.b_body_nt)[low]
    # shared data README: at |lat| < 40 deg the storm pass minus IGRF-14 is [-166, -6, -11] nT
    np.testing.assert_allclose(d.mean(axis=0), [-166.0, -6.0, -11.0], atol=2.0)


def _lr1b_cdf(path: Path, rows: np.ndarray, *, drop: str | None = None) -> None:
    from cdflib.cdfwrite import CDF
    from cdflib.epochs import CDFepoch

    from orbitcal.timescales import parse_time_values

    t, _ = parse_time_values(rows[:, 0])
    num = rows[:, 1:].astype(np.float64)
    variables = {
        "Timestamp": (CDF.CDF_EPOCH, CDFepoch.timestamp_to_cdfepoch(t), "-"),
        "Latitude": (CDF.CDF_REAL8, num[:, 0], "deg"),
        "Longitude": (CDF.CDF_REAL8, num[:, 1], "deg"),
        "Radius": (CDF.CDF_REAL8, num[:, 2], "m"),
        "B_VFM": (CDF.CDF_REAL8, num[:, 3:6], "nT"),
        "B_NEC": (CDF.CDF_REAL8, num[:, 6:9], "nT"),
        "q_NEC_CRF": (CDF.CDF_REAL8, num[:, 13:17], "-"),
        "Flags_B": (CDF.CDF_UINT1, np.array([0, 1, 0, 0], dtype=np.uint8), "-"),
    }
    cdf = CDF(str(path))
    for name, (dtype, data, units) in variables.items():
        if name == drop:
            continue
        dims = [] if np.ndim(data) == 1 else [np.shape(data)[1]]
        spec = {
            "Variable": name,
            "Data_Type": dtype,
            "Num_Elements": 1,
            "Rec_Vary": True,
            "Dim_Sizes": dims,
        }
        cdf.write_var(spec, var_attrs={"UNITS": units}, var_data=data)
    cdf.close()


@pytest.fixture(scope="module")
def grace_rows() -> np.ndarray:
    text = (AUTH / "GRACE_A_MAG_20100101_4rows.csv").read_text().splitlines()
    return np.array([line.split(",") for line in text if not line.startswith("#")], dtype=object)


def test_lr1b_b_vfm_with_q_nec_crf_gives_the_instrument_frame(
    tmp_path: Path, grace_rows: np.ndarray
) -> None:
    """The table's quaternion takes the GCRS field into the instrument frame exactly."""
    path = tmp_path / "SW_OPER_MAGA_LR_1B_20100101T000000_20100101T235959_0602_MDR_MAG_LR.cdf"
    _lr1b_cdf(path, grace_rows)
    res = ingest_swarm(path)
    t = res.telemetry
    assert t is not None and len(t) == 4
    num = grace_rows[:, 1:].astype(np.float64)
    np.testing.assert_allclose(t.b_raw_nt, num[:, 3:6])  # B_VFM taken as measured
    # B_NEC_raw in NEC -> ITRS -> GCRS, then into the body with the table's quaternion: B_FGM
    b_gcrs = frames.itrs_to_gcrs(frames.nec_to_itrs(num[:, 6:9], t.r_itrs_km), t.t_utc_s)
    np.testing.assert_allclose(frame_to_body(b_gcrs, t.q_wxyz), num[:, 3:6], atol=1e-6)
    assert res.summary.flags["Flags_B"] == {"bit 0": 1}


def test_lr1b_b_nec_choice(tmp_path: Path, grace_rows: np.ndarray) -> None:
    path = tmp_path / "lr1b.cdf"
    _lr1b_cdf(path, grace_rows)
    t = ingest_swarm(path, options=SwarmOptions(field="B_NEC")).telemetry
    assert t is not None
    num = grace_rows[:, 1:].astype(np.float64)
    b_gcrs = frames.itrs_to_gcrs(frames.nec_to_itrs(num[:, 6:9], t.r_itrs_km), t.t_utc_s)
    np.testing.assert_allclose(frame_to_body(b_gcrs, t.q_wxyz), num[:, 6:9], atol=1e-6)


def test_b_vfm_without_its_quaternion_is_refused(tmp_path: Path, grace_rows: np.ndarray) -> None:
    path = tmp_path / "lr1b.cdf"
    _lr1b_cdf(path, grace_rows, drop="q_NEC_CRF")
    with pytest.raises(IngestError, match="q_NEC_CRF is needed") as info:
        ingest_swarm(path, options=SwarmOptions(field="B_VFM"))
    assert info.value.field == "q_NEC_CRF"


def test_a_missing_variable_is_named(tmp_path: Path, grace_rows: np.ndarray) -> None:
    path = tmp_path / "lr1b.cdf"
    _lr1b_cdf(path, grace_rows, drop="Radius")
    with pytest.raises(IngestError, match="no Radius variable") as info:
        ingest_swarm(path)
    assert info.value.field == "Radius"


def test_a_truncated_cdf_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "cut.cdf"
    path.write_bytes(VIRES.with_suffix(".cdf").read_bytes()[:20_000])
    with pytest.raises(IngestError, match=r"cut\.cdf: not a readable CDF"):
        ingest_swarm(path)


def test_a_truncated_csv_names_the_line(tmp_path: Path) -> None:
    lines = VIRES.with_suffix(".csv").read_text().splitlines()
    path = tmp_path / "cut.csv"
    path.write_text("\n".join([*lines[:50], lines[50][:40]]) + "\n")
    with pytest.raises(IngestError, match=r"cut.csv:51: .*truncated"):
        ingest_swarm(path)


def test_a_foreign_csv_layout_is_refused(tmp_path: Path) -> None:
    text = VIRES.with_suffix(".csv").read_text().replace("B_NEC", "B_XYZ")
    path = tmp_path / "foreign.csv"
    path.write_text(text)
    with pytest.raises(IngestError, match="neither B_VFM nor B_NEC"):
        ingest_swarm(path)


def test_the_cli_swarm(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.ndjson"
    assert main(["ingest", "swarm", str(VIRES.with_suffix(".cdf")), "--out", str(out)]) == 0
    assert "Swarm A (Swarm): 192 rows" in capsys.readouterr().out
    assert len(out.read_text().splitlines()) == 192
    code = main(["ingest", "swarm", str(tmp_path / "none.cdf"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no such file" in err
