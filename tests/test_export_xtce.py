"""``xtce`` (issue 21) checked by its consumers: the XTCE 1.2 schema (offline), the JavaScript
algorithm run by ``node`` exactly as Yamcs binds it, and the MathAlgorithms' postfix evaluated
as Yamcs compiles it; each equal to ``orbitcal apply`` to 1e-6 nT where the form is exact."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest
from export_consumers import (
    NS,
    run_math_algorithms,
    run_yamcs_javascript,
    validate_xtce,
    xtce_schema,
    xtce_values,
)
from export_worlds import ALL_METHODS, EXACT_NT, Fitted, fitted

from orbitcal.export import ExportOptions, affine_part, calibration_form, evaluate, export

RAW = ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW")


@pytest.fixture(scope="module")
def schema() -> Any:
    return xtce_schema()


def _xtce(f: Fitted, **options: Any) -> bytes:
    result = export(f.document, ExportOptions(format="xtce", **options))
    assert result.content is not None and result.media_type == "application/xml"
    return result.content


def _notes(root: ET.Element) -> str:
    return " ".join(n.text or "" for n in root.iterfind(".//x:Note", NS))


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk", "linear", "lmbp", "twostep"])
def test_xtce_is_valid_xtce_1_2(method: str, schema: Any, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, method)
    xml = _xtce(f)
    errors = validate_xtce(xml, schema)
    assert errors == [], errors[0][:2000]
    root = ET.fromstring(xml)
    assert root.tag == "{http://www.omg.org/spec/XTCE/20180204}SpaceSystem"
    notes = _notes(root)
    assert f"calibration version: {f.document['version']}" in notes
    assert "document SHA-256: " in notes and "reference field: IGRF-14" in notes


def test_schema_rejects_a_broken_document(schema: Any, swarm_a_temperature_world: Any) -> None:
    """The validation has teeth: an unknown dataSource, or a misspelt element, fails."""
    xml = _xtce(fitted(swarm_a_temperature_world, "linear-hk")).decode()
    assert validate_xtce(
        xml.replace('dataSource="local"', 'dataSource="remote"', 1).encode(), schema
    )
    assert validate_xtce(xml.replace("xtce:AlgorithmText", "xtce:AlgoText").encode(), schema)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_javascript_in_node_equals_apply(method: str, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, method)
    hk = {"temperature": "MAG_TEMP", "mtq_x": "/SAT/MTQ_X"}
    raw = ("MAGX", "MAGY", "MAGZ")
    root = ET.fromstring(_xtce(f, raw_names=raw, hk_names=hk))
    form = calibration_form(f.document)
    hk_params = [hk.get(c, c.upper()) for c in form.hk_names]
    # a qualified name refers to the mission's parameter: not defined here
    names = {p.get("name") for p in root.iterfind(".//x:Parameter", NS)}
    if form.hk_names:
        assert "MAG_TEMP" in names and "/SAT/MTQ_X" not in names and "MTQ_Y" in names
    rows = np.flatnonzero(f.holdout)
    x = None if f.x_hk is None else f.x_hk[rows]
    values = xtce_values(root, raw, f.telemetry.b_raw_nt[rows], hk_params, x)
    b_js = run_yamcs_javascript(root, values, len(rows))
    assert np.max(np.abs(b_js - f.b_apply_nt[rows])) < EXACT_NT


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk"])
def test_math_algorithm_postfix_equals_the_affine_part(
    method: str, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, method)
    root = ET.fromstring(_xtce(f))
    form = calibration_form(f.document)
    values = xtce_values(
        root, RAW, f.telemetry.b_raw_nt, [c.upper() for c in form.hk_names], f.x_hk
    )
    outputs, b_lin = run_math_algorithms(root, values)
    assert outputs == ["MAG_X_CAL_LIN", "MAG_Y_CAL_LIN", "MAG_Z_CAL_LIN"]
    expected = evaluate(affine_part(form), f.telemetry.b_raw_nt, f.x_hk)
    assert np.max(np.abs(b_lin - expected)) < EXACT_NT
    if method == "linear-hk":  # exact: the postfix is orbitcal apply
        assert np.max(np.abs(b_lin - f.b_apply_nt)) < EXACT_NT
    else:  # stated loss: the header says the affine part is less than the network
        assert "less than the whole lmbp-hk model" in _notes(root)
        assert np.max(np.abs(b_lin - f.b_apply_nt)) > 0.1


def test_stated_loss_is_written_when_measured(swarm_a_temperature_world: Any) -> None:
    from orbitcal.export import held_out_loss

    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
    notes = _notes(ET.fromstring(_xtce(f, loss=loss)))
    assert f"held-out RMS of this form: {loss.affine_rms_nt:.6g} nT" in notes
    assert f"{loss.full_rms_nt:.6g} nT for the whole model" in notes


# --- issue 45: what Yamcs reads of the file (checked in a real Yamcs: test_export_yamcs_real.py) --


def _params(root: ET.Element) -> dict[str, ET.Element]:
    return {str(p.get("name")): p for p in root.iterfind(".//x:Parameter", NS)}


@pytest.mark.parametrize("inputs", ["local", "telemetered"])
def test_inputs_route_persistence_and_descriptions(
    inputs: str, schema: Any, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    xml = _xtce(f, yamcs_inputs=inputs)
    assert validate_xtce(xml, schema) == []
    root = ET.fromstring(xml)
    params = _params(root)
    for name, p in params.items():
        props = p.find("x:ParameterProperties", NS)
        assert props is not None
        source = props.get("dataSource")
        # persistence only where Yamcs reads it (local parameters), and off: the version rule
        assert props.get("persistence") == ("false" if source == "local" else None), name
        assert p.get("shortDescription"), name
    assert params["MAG_X_RAW"].find("x:ParameterProperties", NS).get("dataSource") == inputs  # type: ignore[union-attr]
    assert params["TEMPERATURE"].find("x:ParameterProperties", NS).get("dataSource") == inputs  # type: ignore[union-attr]
    assert "NOT the calibration" in str(params["MAG_X_CAL_LIN"].get("shortDescription"))
    assert "equals orbitcal apply" in str(params["MAG_X_CAL"].get("shortDescription"))
    # the header's notes in the LongDescription Yamcs keeps, with the version rule
    long = root.findtext("x:LongDescription", namespaces=NS) or ""
    assert "after every (re)start of Yamcs the coefficients are this file's" in long
    assert "less than the whole lmbp-hk model" in long and "document SHA-256: " in long
    # every input of the JavaScript algorithm is mandatory; the MathAlgorithms wait for it
    algo = root.find(".//x:CustomAlgorithm", NS)
    assert algo is not None
    mandatory = {e.text for e in algo.iterfind(".//x:AncillaryData", NS)}
    names = {e.get("inputName") for e in algo.iterfind(".//x:InputParameterInstanceRef", NS)}
    assert mandatory == names and {"raw_x", "hk_4", "version", "layout"} <= names
    triggers = [
        e.get("parameterRef")
        for m in root.iterfind(".//x:MathAlgorithm", NS)
        for e in m.iterfind(".//x:OnParameterUpdateTrigger", NS)
    ]
    assert triggers == ["MAG_X_CAL", "MAG_Y_CAL", "MAG_Z_CAL"]


def test_qualified_inputs_need_every_input_qualified(swarm_a_temperature_world: Any) -> None:
    from orbitcal.export import ExportError

    f = fitted(swarm_a_temperature_world, "linear-hk")
    raw = ("/SAT/MX", "/SAT/MY", "/SAT/MZ")
    with pytest.raises(ExportError, match="not: MAG_X_RAW, MAG_Y_RAW"):
        _xtce(f, yamcs_inputs="qualified")
    with pytest.raises(ExportError, match="not: TEMPERATURE, MTQ_X"):
        _xtce(f, yamcs_inputs="qualified", raw_names=raw)
    hk = {c: f"/SAT/{c.upper()}" for c in calibration_form(f.document).hk_names}
    root = ET.fromstring(_xtce(f, yamcs_inputs="qualified", raw_names=raw, hk_names=hk))
    assert {"MAG_X_RAW", "TEMPERATURE"}.isdisjoint(_params(root))


def test_javascript_waits_for_every_input_and_refuses_another_layout(
    swarm_a_temperature_world: Any,
) -> None:
    """Rows with a missing input (no housekeeping yet) give no output and no error; a coefficient
    set of another layout gives none either (the guard the real Yamcs test also meets)."""
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    root = ET.fromstring(_xtce(f))
    form = calibration_form(f.document)
    hk = [c.upper() for c in form.hk_names]
    rows = np.flatnonzero(f.holdout)[:4]
    assert f.x_hk is not None
    x = f.x_hk[rows].astype(object)
    x[:2, 0] = None  # the temperature has not arrived for the first two rows
    values = xtce_values(root, RAW, f.telemetry.b_raw_nt[rows], hk, f.x_hk[rows])
    for j, name in enumerate(hk):
        values[name] = x[:, j]
    out = run_yamcs_javascript(root, values, len(rows))
    assert np.all(np.isnan(out[:2]))  # null outputs: nothing set
    assert np.max(np.abs(out[2:] - f.b_apply_nt[rows[2:]])) < EXACT_NT
    values["MAGCAL_LAYOUT"] = "affine:hk=0:"
    assert np.all(np.isnan(run_yamcs_javascript(root, values, len(rows))))
