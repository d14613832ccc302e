"""``xtce`` (issue 21) checked by its consumers: the XTCE 1.2 schema (offline), the JavaScript
algorithm run by ``node`` exactly as Yamcs binds it, and the MathAlgorithms' postfix evaluated
as Yamcs compiles it; each equal to ``orbitcal apply`` to 1e-6 nT where the form is exact."""

from __future__ import annotations

import json
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_worlds import EXACT_NT, Fitted, fitted

from orbitcal.export import ExportOptions, affine_part, calibration_form, evaluate, export

SCHEMA_DIR = Path(__file__).parent / "authorities" / "xtce"
NS = {"x": "http://www.omg.org/spec/XTCE/20180204"}

#: Yamcs's binding of a JavaScript CustomAlgorithm (yamcs-core ScriptAlgorithmExecutorFactory.
#: generateFunctionCode, ScriptAlgorithmExecutor.execute): the text becomes the body of
#: ``function NAME(inputs..., outputs...)`` (each line indented by 4), inputs are objects whose
#: ``value`` is the engineering value, outputs ``{value: null, rawValue: null, updated: true}``.
NODE_YAMCS = r"""
const vm = require("vm");
const spec = JSON.parse(require("fs").readFileSync(0, "utf8"));
const args = spec.inputs.concat(spec.outputs).join(", ");
const body = spec.text.split(/\r?\n/).map(l => "    " + l).join("\n");
const src = "function " + spec.name + "(" + args + ") {\n" + body + "\n}";
const ctx = vm.createContext({});
vm.runInContext(src, ctx);
const fn = ctx[spec.name];
const ins = spec.inputs.map(() => ({value: null}));
const outs = spec.outputs.map(() => ({value: null, rawValue: null, updated: true}));
const result = [];
for (const row of spec.rows) {
  row.forEach((v, i) => { ins[i].value = v; });
  outs.forEach(o => { o.value = null; o.rawValue = null; });
  fn.apply(null, ins.concat(outs));
  result.push(outs.map(o => o.value));
}
process.stdout.write(JSON.stringify(result));
"""


def _schema() -> Any:
    import xmlschema

    return xmlschema.XMLSchema(
        str(SCHEMA_DIR / "SpaceSystemV1.2.xsd"),
        locations=[("http://www.w3.org/XML/1998/namespace", str(SCHEMA_DIR / "xml.xsd"))],
        allow="local",  # never the network: the W3C import is the local copy
    )


@pytest.fixture(scope="module")
def schema() -> Any:
    return _schema()


def _xtce(f: Fitted, **options: Any) -> bytes:
    result = export(f.document, ExportOptions(format="xtce", **options))
    assert result.content is not None and result.media_type == "application/xml"
    return result.content


def _values(
    root: ET.Element, f: Fitted, hk_params: list[str], raw: tuple[str, ...]
) -> dict[str, Any]:
    """Parameter name -> value per sample: telemetry for raw/hk, initialValue for locals."""
    values: dict[str, Any] = {}
    for p in root.iterfind(".//x:ParameterSet/x:Parameter", NS):
        props = p.find("x:ParameterProperties", NS)
        assert props is not None
        if props.get("dataSource") == "local":
            init = p.get("initialValue")
            assert init is not None, p.get("name")
            try:
                values[p.get("name", "")] = float(init)
            except ValueError:
                values[p.get("name", "")] = init
    b = f.telemetry.b_raw_nt
    for j, name in enumerate(raw):
        values[name] = b[:, j]
    for j, name in enumerate(hk_params):
        assert f.x_hk is not None
        values[name] = f.x_hk[:, j]
    return values


def _run_js(root: ET.Element, values: dict[str, Any], n: int) -> np.ndarray:
    node = shutil.which("node")
    assert node is not None, "node is needed (Debian: apt-get install nodejs)"
    algo = root.find(".//x:CustomAlgorithm", NS)
    assert algo is not None
    text = algo.findtext("x:AlgorithmText", namespaces=NS)
    assert text is not None
    refs = [
        (e.get("parameterRef"), e.get("inputName"))
        for e in algo.iterfind(".//x:InputParameterInstanceRef", NS)
    ]
    outs = [e.get("outputName") for e in algo.iterfind(".//x:OutputParameterRef", NS)]
    rows = []
    for i in range(n):
        row = []
        for ref, _ in refs:
            v = values[str(ref)]
            row.append(float(v[i]) if isinstance(v, np.ndarray) else v)
        rows.append(row)
    spec = {
        "name": "MAGCAL_MagCalibration",
        "text": text,
        "inputs": [name for _, name in refs],
        "outputs": outs,
        "rows": rows,
    }
    out = subprocess.run(
        [node, "-e", NODE_YAMCS], input=json.dumps(spec), capture_output=True, text=True, check=True
    )
    return np.asarray(json.loads(out.stdout), dtype=np.float64)


def _postfix(op: ET.Element, values: dict[str, Any]) -> np.ndarray:
    """Evaluate a MathOperation as Yamcs does (MathOperationCalibratorFactory: operands push,
    a binary operator pops r then l and pushes ``l op r``)."""
    stack: list[Any] = []
    for e in op:
        tag = e.tag.split("}")[1]
        if tag == "ParameterInstanceRefOperand":
            stack.append(values[str(e.get("parameterRef"))])
        elif tag == "ValueOperand":
            stack.append(float(str(e.text)))
        elif tag == "Operator":
            r, l_ = stack.pop(), stack.pop()
            stack.append({"+": l_ + r, "-": l_ - r, "*": l_ * r, "/": l_ / r}[str(e.text)])
        elif tag == "TriggerSet":
            continue
        else:  # pragma: no cover - the generator writes nothing else
            raise AssertionError(tag)
    assert len(stack) == 1, "stack not empty at the end"
    return np.asarray(stack[0], dtype=np.float64)


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk", "linear", "lmbp", "twostep"])
def test_xtce_is_valid_xtce_1_2(method: str, schema: Any, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, method)
    xml = _xtce(f)
    errors = list(schema.iter_errors(xml.decode()))
    assert errors == [], str(errors[0])[:2000]
    root = ET.fromstring(xml)
    assert root.tag == "{http://www.omg.org/spec/XTCE/20180204}SpaceSystem"
    notes = " ".join(n.text or "" for n in root.iterfind(".//x:Note", NS))
    assert f"calibration version: {f.document['version']}" in notes
    assert "document SHA-256: " in notes and "reference field: IGRF-14" in notes


def test_schema_rejects_a_broken_document(schema: Any, swarm_a_temperature_world: Any) -> None:
    """The validation has teeth: an algorithm without its text, or an unknown dataSource, fails."""
    xml = _xtce(fitted(swarm_a_temperature_world, "linear-hk")).decode()
    assert list(schema.iter_errors(xml.replace('dataSource="local"', 'dataSource="remote"', 1)))
    assert list(schema.iter_errors(xml.replace("xtce:AlgorithmText", "xtce:AlgoText")))


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk"])
def test_javascript_in_node_equals_apply(method: str, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, method)
    hk = {"temperature": "MAG_TEMP", "mtq_x": "/SAT/MTQ_X"}
    raw = ("MAGX", "MAGY", "MAGZ")
    root = ET.fromstring(_xtce(f, raw_names=raw, hk_names=hk))
    form = calibration_form(f.document)
    hk_params = [hk.get(c, c.upper()) for c in form.hk_names]
    # a qualified name refers to the mission's parameter: not defined here
    names = {p.get("name") for p in root.iterfind(".//x:Parameter", NS)}
    assert "MAG_TEMP" in names and "/SAT/MTQ_X" not in names and "MTQ_Y" in names
    values = _values(root, f, hk_params, raw)
    rows = np.flatnonzero(f.holdout)
    values = {k: (v[rows] if isinstance(v, np.ndarray) else v) for k, v in values.items()}
    b_js = _run_js(root, values, len(rows))
    assert np.max(np.abs(b_js - f.b_apply_nt[rows])) < EXACT_NT


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk"])
def test_math_algorithm_postfix_equals_the_affine_part(
    method: str, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, method)
    root = ET.fromstring(_xtce(f))
    form = calibration_form(f.document)
    values = _values(
        root, f, [c.upper() for c in form.hk_names], ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW")
    )
    algos = root.findall(".//x:MathAlgorithm", NS)
    assert len(algos) == 3
    b_lin = np.column_stack([_postfix(a.find("x:MathOperation", NS), values) for a in algos])  # type: ignore[arg-type]
    assert [a.find("x:MathOperation", NS).get("outputParameterRef") for a in algos] == [  # type: ignore[union-attr]
        "MAG_X_CAL_LIN",
        "MAG_Y_CAL_LIN",
        "MAG_Z_CAL_LIN",
    ]
    expected = evaluate(affine_part(form), f.telemetry.b_raw_nt, f.x_hk)
    assert np.max(np.abs(b_lin - expected)) < EXACT_NT
    if method == "linear-hk":  # exact: the postfix is orbitcal apply
        assert np.max(np.abs(b_lin - f.b_apply_nt)) < EXACT_NT
    else:  # stated loss: the header says the affine part is less than the network
        notes = " ".join(n.text or "" for n in root.iterfind(".//x:Note", NS))
        assert "less than the whole lmbp-hk model" in notes
        assert np.max(np.abs(b_lin - f.b_apply_nt)) > 0.1


def test_stated_loss_is_written_when_measured(swarm_a_temperature_world: Any) -> None:
    from orbitcal.export import held_out_loss

    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
    root = ET.fromstring(_xtce(f, loss=loss))
    notes = " ".join(n.text or "" for n in root.iterfind(".//x:Note", NS))
    assert f"held-out RMS of this form: {loss.affine_rms_nt:.6g} nT" in notes
    assert f"{loss.full_rms_nt:.6g} nT for the whole model" in notes
