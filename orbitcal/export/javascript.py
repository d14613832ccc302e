"""The JavaScript body of the Yamcs ``CustomAlgorithm`` (ES5: Yamcs runs it in Nashorn).

Yamcs wraps the text as ``function NAME(in_1, ..., out_1, ...) { <text> }`` and binds each input
as an object whose ``value`` is the engineering value and each output as an object whose
``value`` the text sets (Yamcs ``ScriptAlgorithmExecutorFactory.generateFunctionCode`` and
``docs/server-manual/mdb/algorithm-definitions.rst``). Inputs here: ``raw_x, raw_y, raw_z``
[nT], ``hk_0..hk_{k-1}`` (housekeeping, table units), then one input per coefficient (local
parameters, named as in :meth:`AffineForm.coefficients` / :meth:`NetworkForm.coefficients`);
outputs ``cal_x, cal_y, cal_z`` [nT]. ``tanh`` is written with ``Math.exp`` (ES5 has no
``Math.tanh``).

Two more inputs, ``version`` and ``layout`` (the ``<SYS>_VERSION``/``_LAYOUT`` local
parameters), carry the coefficients' version and shape. The text:

* sets no output while any input has no value (Yamcs also holds it back: every input is a
  ``Yamcs:AlgorithmMandatoryInput``), so a raw row before housekeeping gives no calibrated value,
  never a TypeError or a zero;
* refuses coefficients of another layout than the file's (no output, a warning event);
* computes with coefficients of another version than the file's (set by ``yamcs-push``) and
  says so once per version with an event (``Yamcs.info``; the version rule, docs/yamcs.md).

Events go through Yamcs's ``Yamcs`` object when it is there (``AlgorithmFunctions``); elsewhere
(node in the tests) they are skipped.
"""

from __future__ import annotations

import json

from orbitcal.export.names import js_comment
from orbitcal.export.product import AffineForm, NetworkForm

__all__ = ["INPUT_RAW", "OUTPUTS", "algorithm_text", "hk_inputs"]

INPUT_RAW = ("raw_x", "raw_y", "raw_z")
OUTPUTS = ("cal_x", "cal_y", "cal_z")


def hk_inputs(n: int) -> list[str]:
    return [f"hk_{j}" for j in range(n)]


def _matrix(prefix: str, rows: int, cols: int) -> str:
    body = ", ".join(
        "[" + ", ".join(f"{prefix}_{i}_{j}.value" for j in range(cols)) + "]" for i in range(rows)
    )
    return f"[{body}]"


def _vector(prefix: str, n: int) -> str:
    return "[" + ", ".join(f"{prefix}_{i}.value" for i in range(n)) + "]"


def _guard(k: int, version: int, layout: str, system: str) -> list[str]:
    """The lines that stop before any output: a missing input, another layout; and the event
    of another version (``seen``: a global of the script engine, one per space system)."""
    names = [*INPUT_RAW, *hk_inputs(k), "version", "layout"]
    seen = f"orbitcal_{system.replace('-', '_')}_seen"
    # Every piece of text is a JSON literal: names reach the script only as escaped strings.
    event = (
        f"{json.dumps(system + ': computing with coefficients of version ')} + version.value + "
        + json.dumps(
            f", set at run time; this MDB holds version {version}, which every restart serves "
            "again (load the XTCE of version "
        )
        + " + version.value + ' to keep it)'"
    )
    refuse = (
        f"{json.dumps(system + ': coefficients of layout ')} + layout.value + "
        "' refused: this algorithm was generated for ' + FILE_LAYOUT + "
        "'; load the matching XTCE'"
    )
    return [
        f"var FILE_VERSION = {version};",
        f"var FILE_LAYOUT = {json.dumps(layout)};",
        "var inputs = [" + ", ".join(names) + "];",
        "for (var q = 0; q < inputs.length; q++) {",
        "  if (inputs[q] === null || inputs[q] === undefined || inputs[q].value === null"
        " || inputs[q].value === undefined) { return; }",
        "}",
        "var events = typeof Yamcs === 'undefined' ? null : Yamcs;",
        "if (String(layout.value) !== FILE_LAYOUT) {",
        f"  if (events !== null && this.{seen}_layout !== String(layout.value)) {{",
        f"    events.warning('MagCalibration', {refuse});",
        "  }",
        f"  this.{seen}_layout = String(layout.value);",
        "  return;",
        "}",
        f"if (Number(version.value) !== FILE_VERSION && this.{seen} !== Number(version.value)) {{",
        f"  this.{seen} = Number(version.value);",
        f"  if (events !== null) {{ events.info('MagCalibration', {event}); }}",
        "}",
    ]


def algorithm_text(
    form: AffineForm | NetworkForm,
    header: list[str],
    *,
    version: int,
    layout: str,
    system: str,
) -> str:
    """The algorithm text (function body) computing ``cal_*`` from the inputs."""
    k = len(form.hk_names)
    lines = [f"// {js_comment(h)}" for h in header]
    lines += _guard(k, version, layout, system)
    lines.append(
        "var x = [raw_x.value, raw_y.value, raw_z.value"
        + "".join(f", hk_{j}.value" for j in range(k))
        + "];"
    )
    if isinstance(form, AffineForm):
        lines += [
            f"var M = {_matrix('M', 3, 3)};",
            f"var o = {_vector('O', 3)};",
            f"var K = {_matrix('K', 3, k)};",
            "var b = [0, 0, 0];",
            "for (var i = 0; i < 3; i++) {",
            "  var s = x[i] - o[i];",
            f"  for (var j = 0; j < {k}; j++) {{ s -= K[i][j] * x[3 + j]; }}",
            "  b[i] = s;",
            "}",
            "var out = [0, 0, 0];",
            "for (var r = 0; r < 3; r++) {",
            "  out[r] = M[r][0] * b[0] + M[r][1] * b[1] + M[r][2] * b[2];",
            "}",
        ]
    else:
        n, h = form.n_in, form.n_hidden
        act = (
            "1 - 2 / (Math.exp(2 * z) + 1)"
            if form.activation == "tanh"
            else "1 / (1 + Math.exp(-z))"
        )
        lines += [
            f"var inLo = {_vector('IN_LO', n)};",
            f"var inGain = {_vector('IN_GAIN', n)};",
            f"var W1 = {_matrix('W1', h, n)};",
            f"var b1 = {_vector('B1', h)};",
            f"var W2 = {_matrix('W2', 3, h)};",
            f"var b2 = {_vector('B2', 3)};",
            f"var L = {_matrix('L', 3, n)};",
            f"var outLo = {_vector('OUT_LO', 3)};",
            f"var outGain = {_vector('OUT_GAIN', 3)};",
            "var u = [];",
            f"for (var i = 0; i < {n}; i++) {{",
            "  u.push((x[i] - inLo[i]) * inGain[i] - (inGain[i] > 0 ? 1 : 0));",
            "}",
            "var hid = [];",
            f"for (var j = 0; j < {h}; j++) {{",
            "  var z = b1[j];",
            f"  for (var i = 0; i < {n}; i++) {{ z += W1[j][i] * u[i]; }}",
            f"  hid.push({act});",
            "}",
            "var out = [0, 0, 0];",
            "for (var r = 0; r < 3; r++) {",
            "  var y = b2[r];",
            f"  for (var j = 0; j < {h}; j++) {{ y += W2[r][j] * hid[j]; }}",
            f"  for (var i = 0; i < {n}; i++) {{ y += L[r][i] * u[i]; }}",
            "  out[r] = outGain[r] > 0 ? (y + 1) / outGain[r] + outLo[r] : outLo[r];",
            "}",
        ]
    lines += ["cal_x.value = out[0];", "cal_y.value = out[1];", "cal_z.value = out[2];"]
    return "\n".join(lines) + "\n"
