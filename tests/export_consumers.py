"""The consumers of the exports, driven as the real tools drive them (issue 21).

Used by ``tests/test_export_*.py`` and by ``tools/export_table.py`` (the docs' table):

* :func:`validate_xtce` — the XTCE 1.2 schema, offline (``tests/authorities/xtce/``);
* :func:`run_yamcs_javascript` — the ``CustomAlgorithm`` run by ``node`` with Yamcs's binding;
* :func:`run_math_algorithms` — the ``MathAlgorithm`` postfix as Yamcs evaluates it;
* :func:`run_cosmos` — the plugin fragment processed by ``openc3``'s ``PacketConfig``;
* :func:`run_c_header` — the header compiled with ``cc`` and run;
* :func:`run_polynomial` — the per-axis coefficients through ``openc3``'s ``PolynomialConversion``.

Each takes raw readings ``(N, 3)`` [nT] and housekeeping ``(N, k)`` in the calibration's order
and returns the consumer's ``(N, 3)`` output [nT].
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

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


def xtce_schema() -> Any:
    """The XTCE 1.2 schema with the W3C ``xml.xsd`` import mapped to the local copy."""
    import xmlschema

    return xmlschema.XMLSchema(
        str(SCHEMA_DIR / "SpaceSystemV1.2.xsd"),
        locations=[("http://www.w3.org/XML/1998/namespace", str(SCHEMA_DIR / "xml.xsd"))],
        allow="local",  # never the network
    )


def validate_xtce(xml: bytes, schema: Any = None) -> list[str]:
    """Schema errors of an XTCE document (empty: valid)."""
    schema = schema or xtce_schema()
    return [str(e) for e in schema.iter_errors(xml.decode("utf-8"))]


def xtce_values(
    root: ET.Element,
    raw_names: tuple[str, ...],
    b_raw_nt: np.ndarray,
    hk_names: list[str],
    x_hk: np.ndarray | None,
) -> dict[str, Any]:
    """Parameter name -> value: the telemetry for raw/hk (arrays), ``initialValue`` for the
    local parameters that have one (the coefficients; local inputs have none)."""
    values: dict[str, Any] = {}
    inputs = {*raw_names, *hk_names}
    for p in root.iterfind(".//x:ParameterSet/x:Parameter", NS):
        props = p.find("x:ParameterProperties", NS)
        if props is not None and props.get("dataSource") == "local":
            init = p.get("initialValue")
            if p.get("name") in inputs:
                continue
            assert init is not None, p.get("name")
            try:
                values[p.get("name", "")] = float(init)
            except ValueError:
                values[p.get("name", "")] = init
    for j, name in enumerate(raw_names):
        values[name] = b_raw_nt[:, j]
    for j, name in enumerate(hk_names):
        assert x_hk is not None
        values[name] = x_hk[:, j]
    return values


def run_yamcs_javascript(root: ET.Element, values: dict[str, Any], n: int) -> np.ndarray:
    """Outputs of the SpaceSystem's ``CustomAlgorithm`` over ``n`` samples, run by node."""
    node = shutil.which("node")
    assert node is not None, "node is needed (Debian: apt-get install nodejs)"
    algo = root.find(".//x:CustomAlgorithm", NS)
    assert algo is not None
    text = algo.findtext("x:AlgorithmText", namespaces=NS)
    assert text is not None
    refs = [
        (str(e.get("parameterRef")), str(e.get("inputName")))
        for e in algo.iterfind(".//x:InputParameterInstanceRef", NS)
    ]
    outs = [e.get("outputName") for e in algo.iterfind(".//x:OutputParameterRef", NS)]

    def one(v: Any) -> Any:  # None: no value yet (Yamcs binds the input with a null value)
        return None if v is None else float(v)

    rows = [
        [
            one(values[ref][i]) if isinstance(values[ref], np.ndarray) else values[ref]
            for ref, _ in refs
        ]
        for i in range(n)
    ]
    spec = {
        "name": "MAGCAL_" + str(algo.get("name")),
        "text": text,
        "inputs": [name for _, name in refs],
        "outputs": outs,
        "rows": rows,
    }
    out = subprocess.run(
        [node, "-e", NODE_YAMCS],
        input=json.dumps(spec),
        capture_output=True,
        text=True,
        check=True,
    )
    return np.asarray(json.loads(out.stdout), dtype=np.float64)


def eval_postfix(op: ET.Element, values: dict[str, Any]) -> np.ndarray:
    """A MathOperation as Yamcs evaluates it (MathOperationCalibratorFactory: operands push, a
    binary operator pops ``r`` then ``l`` and pushes ``l op r``)."""
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
        elif tag != "TriggerSet":
            raise AssertionError(f"unexpected {tag} in a MathOperation")
    assert len(stack) == 1, "stack not empty at the end"
    return np.asarray(stack[0], dtype=np.float64)


def run_math_algorithms(root: ET.Element, values: dict[str, Any]) -> tuple[list[str], np.ndarray]:
    """``(output parameters, (N, 3) outputs)`` of the SpaceSystem's MathAlgorithms."""
    ops = [a.find("x:MathOperation", NS) for a in root.findall(".//x:MathAlgorithm", NS)]
    assert all(op is not None for op in ops)
    names = [str(op.get("outputParameterRef")) for op in ops if op is not None]
    return names, np.column_stack([eval_postfix(op, values) for op in ops if op is not None])


def _render_erb(text: str, variables: dict[str, str]) -> str:
    """The plugin install's ERB step for ``<%= name %>`` references (all the fragment uses)."""
    return re.sub(r"<%=\s*(\w+)\s*%>", lambda m: variables[m.group(1)], text)


def run_cosmos(
    files: dict[str, bytes],
    hk_items: list[str],
    b_raw_nt: np.ndarray,
    x_hk: np.ndarray | None,
    *,
    cal_items: tuple[str, str, str] = ("MAG_X_CAL", "MAG_Y_CAL", "MAG_Z_CAL"),
    raw_items: tuple[str, str, str] = ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW"),
) -> tuple[np.ndarray, Any]:
    """Read the DERIVED items of a mission packet (target INST, packet MAG) holding each sample,
    with the fragment's telemetry file processed by openc3 after the ERB step. Returns the
    outputs and the conversion object COSMOS built."""
    from openc3.packets.packet_config import PacketConfig

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for name, data in files.items():
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            (out / name).write_bytes(data)
        variables = json.loads((out / "vars.json").read_text())
        target = out / "targets" / "MAGCAL"
        rendered = out / "magcal_tlm.txt"
        text = (target / "cmd_tlm" / "magcal_tlm.txt").read_text()
        rendered.write_text(_render_erb(text, variables))
        mission = out / "mission_tlm.txt"
        lines = ['TELEMETRY INST MAG BIG_ENDIAN "magnetometer packet"']
        lines += [f'  APPEND_ITEM {n} 64 FLOAT "input"' for n in [*raw_items, *hk_items]]
        mission.write_text("\n".join(lines) + "\n")
        sys.path.insert(0, str(target / "lib"))
        sys.modules.pop("mag_calibration", None)
        try:
            config = PacketConfig()
            config.process_file(str(mission), "INST")
            config.process_file(str(rendered), "INST")
            packet = config.telemetry["INST"]["MAG"]
            conversion = packet.get_item(cal_items[0]).read_conversion
            b = np.empty((len(b_raw_nt), 3))
            for k in range(len(b_raw_nt)):
                for j, name in enumerate(raw_items):
                    packet.write(name, float(b_raw_nt[k, j]))
                for j, name in enumerate(hk_items):
                    assert x_hk is not None
                    packet.write(name, float(x_hk[k, j]))
                b[k] = [packet.read(n) for n in cal_items]
        finally:
            sys.path.remove(str(target / "lib"))
            sys.modules.pop("mag_calibration", None)
    return b, conversion


MAIN_C = r"""
#include <stdio.h>
#include "orbitcal_magcal.h"

int main(void)
{
    double raw[3], hk[ORBITCAL_MAGCAL_N_HK + 1], out[3];
    float rawf[3], hkf[ORBITCAL_MAGCAL_N_HK + 1], outf[3];
    int i;
    printf("%d %d\n", orbitcal_magcal_table_ok(), ORBITCAL_MAGCAL_VERSION);
    while (scanf("%lf %lf %lf", &raw[0], &raw[1], &raw[2]) == 3) {
        for (i = 0; i < ORBITCAL_MAGCAL_N_HK; i++) if (scanf("%lf", &hk[i]) != 1) return 2;
        for (i = 0; i < 3; i++) rawf[i] = (float)raw[i];
        for (i = 0; i < ORBITCAL_MAGCAL_N_HK; i++) hkf[i] = (float)hk[i];
        orbitcal_magcal_apply_f64(raw, hk, out);
        orbitcal_magcal_apply_f32(rawf, hkf, outf);
        printf("%.17g %.17g %.17g %.9g %.9g %.9g\n", out[0], out[1], out[2],
               (double)outf[0], (double)outf[1], (double)outf[2]);
    }
    return 0;
}
"""


def run_c_header(
    header: bytes, b_raw_nt: np.ndarray, x_hk: np.ndarray | None
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Compile a program with the header (``cc -std=c99 -Wall -Werror -pedantic``) and run it:
    ``(table_ok, version, float64 outputs, float32 outputs)``."""
    cc = shutil.which("cc")
    assert cc is not None, "a C compiler (cc) is needed"
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "orbitcal_magcal.h").write_bytes(header)
        (d / "main.c").write_text(MAIN_C)
        exe = d / "magcal"
        subprocess.run(
            [
                cc,
                "-std=c99",
                "-Wall",
                "-Werror",
                "-pedantic",
                "-O2",
                "-o",
                str(exe),
                str(d / "main.c"),
            ],
            check=True,
            capture_output=True,
        )
        inputs = b_raw_nt if x_hk is None else np.hstack([b_raw_nt, x_hk])
        text = "\n".join(" ".join(repr(float(v)) for v in row) for row in inputs) + "\n"
        out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    first, *lines = out.stdout.splitlines()
    ok, version = (int(v) for v in first.split())
    values = np.asarray([[float(v) for v in ln.split()] for ln in lines])
    return ok, version, values[:, :3], values[:, 3:]


def run_polynomial(body: dict[str, Any], b_raw_nt: np.ndarray) -> np.ndarray:
    """The polynomial file's COSMOS lines through openc3's ``PolynomialConversion``."""
    from openc3.conversions.polynomial_conversion import PolynomialConversion

    out = np.empty((len(b_raw_nt), 3))
    for axis in body["axes"]:
        words = axis["cosmos"].split()
        assert words[0] == "POLY_READ_CONVERSION"
        conv = PolynomialConversion(*words[1:])
        i = axis["axis"]
        out[:, i] = [conv.call(v, None, None) for v in b_raw_nt[:, i]]
    return out
