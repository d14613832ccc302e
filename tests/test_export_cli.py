"""``orbitcal export`` (CONTRACT sections 2 and 7) and the ``polynomial`` format run by the
one-input tools' own evaluation (OpenC3's ``PolynomialConversion``, XTCE
``PolynomialCalibrator`` terms)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_consumers import run_polynomial
from export_worlds import fitted

from orbitcal.cli import main
from orbitcal.export import affine_part, calibration_form, held_out_loss
from orbitcal.telemetry import write_telemetry

TLE = Path(__file__).parents[1] / "orbitcal" / "data" / "swarm_iss_real_tles.tle"


@pytest.fixture
def files(tmp_path: Path, swarm_a_temperature_world: Any) -> tuple[Path, Path, Any]:
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(f.document, indent=2))
    tel = tmp_path / "tel.parquet"
    write_telemetry(tel, f.telemetry)
    return cal, tel, f


def test_every_format_from_the_command_line(
    files: tuple[Path, Path, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal, tel, f = files
    common = ["--telemetry", str(tel), "--tle", str(TLE), "--norad", "39452"]
    assert main(["export", str(cal), "--format", "json", "--out", str(tmp_path / "c.json")]) == 0
    assert json.loads((tmp_path / "c.json").read_text()) == f.document
    out = tmp_path / "x.xml"
    names = ["--raw-names", "BX,BY,BZ", "--cal-names", "CX,CY,CZ", "--hk-names", "temperature=TMAG"]
    assert main(["export", str(cal), "--format", "xtce", "--out", str(out), *names, *common]) == 0
    root = ET.fromstring(out.read_bytes())
    params = {p.get("name") for p in root.iter("{http://www.omg.org/spec/XTCE/20180204}Parameter")}
    assert {"BX", "BY", "BZ", "CX", "CY", "CZ", "TMAG", "MTQ_X", "CX_LIN"} <= params
    assert "MAG_X_RAW" not in params
    printed = capsys.readouterr().out
    loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
    assert f"affine part {loss.affine_rms_nt:.4f} nT" in printed
    assert f"whole calibration {f.document['metrics']['holdout_rms_nt']:.4f} nT" in printed
    assert main(["export", str(cal), "--format", "cosmos", "--out", str(tmp_path / "cos")]) == 0
    assert (tmp_path / "cos" / "targets" / "MAGCAL" / "lib" / "mag_calibration.py").is_file()
    assert main(["export", str(cal), "--format", "cosmos", "--out", str(tmp_path / "c.zip")]) == 0
    assert "vars.json" in zipfile.ZipFile(tmp_path / "c.zip").namelist()
    inst = tmp_path / "yamcs"
    assert main(["export", str(cal), "--format", "yamcs-instance", "--out", str(inst)]) == 0
    assert (inst / "etc" / "yamcs.magcal.yaml").is_file() and (
        inst / "mdb" / "MAGCAL.xml"
    ).is_file()
    assert "org.yamcs.YamcsServer --etc-dir etc" in capsys.readouterr().out
    assert main(["export", str(cal), "--format", "c-header", "--out", str(tmp_path / "m.h")]) == 0
    assert "ORBITCAL_MAGCAL_CRC32_F64" in (tmp_path / "m.h").read_text()


def test_polynomial_through_the_tools_own_evaluation(
    files: tuple[Path, Path, Any], tmp_path: Path
) -> None:
    cal, tel, f = files
    out = tmp_path / "p.json"
    common = ["--telemetry", str(tel), "--tle", str(TLE), "--norad", "39452"]
    assert main(["export", str(cal), "--format", "polynomial", "--out", str(out), *common]) == 0
    body = json.loads(out.read_text())
    aff = affine_part(calibration_form(f.document))
    rows = np.flatnonzero(f.holdout)
    raw = f.telemetry.b_raw_nt[rows]
    b_poly = run_polynomial(body, raw)
    for axis in body["axes"]:
        i = axis["axis"]
        # XTCE: sum of coefficient * x**exponent over the Terms
        terms = ET.fromstring(axis["xtce"].replace("xtce:", "")).findall("Term")
        xt = sum(
            float(str(t.get("coefficient"))) * raw[:, i] ** int(str(t.get("exponent")))
            for t in terms
        )
        assert np.allclose(xt, b_poly[:, i], rtol=0, atol=1e-9)
        assert axis["coefficients"][1] == aff.M[i, i]
    ref = f.b_apply_nt[rows]
    loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
    assert body["held_out"]["diagonal_rms_nt"] == pytest.approx(loss.diagonal_rms_nt)
    assert np.max(np.abs(b_poly - ref)) == pytest.approx(loss.diagonal_max_abs_diff_nt, rel=1e-9)
    assert any("diagonal of the affine form only" in n for n in body["notes"])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--format", "xtce", "--raw-names", "A,B"], "--raw-names takes three names"),
        (["--format", "xtce", "--cal-names", "MAG_X_RAW,B,C"], "must differ"),
        (["--format", "xtce", "--hk-names", "temperature"], "COLUMN=NAME"),
        (["--format", "xtce", "--hk-names", "temperature=MAG_X_RAW"], "MAG_X_RAW named twice"),
        (["--format", "yamcs-push"], "needs --yamcs-url and --yamcs-instance"),
        (["--format", "xtce", "--yamcs-inputs", "qualified"], "not: MAG_X_RAW, MAG_Y_RAW"),
        (["--format", "yamcs-instance", "--yamcs-instance", "a/b"], "must be a plain name"),
    ],
)
def test_bad_options_exit_2_with_one_line(
    files: tuple[Path, Path, Any],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    message: str,
) -> None:
    cal, _, _ = files
    assert main(["export", str(cal), *args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("orbitcal export: ") and message in err and "\n" not in err


def test_not_a_calibration_document(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"spacecraft": "x"}')
    assert main(["export", str(bad), "--format", "xtce", "--out", str(tmp_path / "o")]) == 2
    assert "not a calibration document" in capsys.readouterr().err


def test_the_command_offers_the_library_formats() -> None:
    from orbitcal.cli import export as cli_export
    from orbitcal.export import FORMATS

    # the CLI keeps its own copy so that `orbitcal --help` imports no numpy
    assert cli_export._FORMATS == FORMATS


def test_polynomial_without_telemetry_states_what_it_knows_of_its_loss(
    swarm_a_temperature_world: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 47: without --telemetry the held-out loss cannot be measured; the command says so,
    how to measure it, and the bound the coefficients give (which the measured loss obeys)."""
    from orbitcal.export.polynomial import LEO_FIELD_MAX_NT

    for method in ("linear", "lmbp-hk"):
        f = fitted(swarm_a_temperature_world, method)
        cal = tmp_path / f"{method}.json"
        cal.write_text(json.dumps(f.document))
        out = tmp_path / f"{method}-p.json"
        assert main(["export", str(cal), "--format", "polynomial", "--out", str(out)]) == 0
        printed = capsys.readouterr().out
        assert "held-out RMS of this form: not measured (export with --telemetry TABLE" in printed
        aff = affine_part(calibration_form(f.document))
        bound = np.abs(aff.M - np.diag(np.diag(aff.M))).sum(axis=1) * LEO_FIELD_MAX_NT
        stated = ", ".join(f"{v:.3g}" for v in bound)
        assert f"change x, y, z by at most {stated} nT at a field of 65,000 nT" in printed
        assert json.loads(out.read_text())["notes"][-1] in printed
        if method == "linear":
            loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
            assert loss.diagonal_max_abs_diff_nt <= float(np.max(bound))
        else:
            assert "housekeeping terms" in printed and "cannot be bounded" in printed
