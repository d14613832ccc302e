"""``xtce``: an XTCE 1.2 SpaceSystem for Yamcs (CONTRACT section 7).

What it holds (namespace ``http://www.omg.org/spec/XTCE/20180204``, valid against the XTCE 1.2
schema, ``tests/authorities/xtce/``):

* the raw axes [nT] and housekeeping inputs as local parameters (settable over REST) or
  telemetered ones (``options.yamcs_inputs``), unless given as qualified references
  (``/MYSAT/MAG_X``) to parameters the mission's MDB already defines;
* the calibrated axes [nT] (``dataSource="derived"``), outputs of a JavaScript
  ``CustomAlgorithm`` that carries the **whole** calibration (the network too, for LM-BP);
* every coefficient as a local parameter (``dataSource="local"``, ``initialValue`` = this
  version, ``persistence="false"``: after a restart the file's version, :data:`VERSION_RULE`),
  so ``yamcs-push`` (``POST .../parameters:batchSet``) installs a new version of the same layout
  without an MDB reload until the next restart; ``<SYS>_VERSION``, ``<SYS>_SHA256`` and
  ``<SYS>_LAYOUT`` say which version is served;
* one strict-XTCE ``MathAlgorithm`` per axis with the affine part in postfix
  (``<CAL>_LIN``): exact for the affine methods, the network's affine part otherwise (its
  description and the header say what it drops). It runs when the JavaScript algorithm has
  computed the same row: Yamcs feeds a MathAlgorithm a missing input as 0, the JavaScript
  algorithm waits for every input (``Yamcs:AlgorithmMandatoryInput``).

Yamcs cannot do this with calibrators: a calibrator sees one parameter (its XTCE reader refuses
other parameters inside one), so cross-axis terms need an algorithm.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from orbitcal.export._text import f64, loss_lines
from orbitcal.export.javascript import INPUT_RAW, OUTPUTS, algorithm_text, hk_inputs
from orbitcal.export.names import xml_text
from orbitcal.export.options import ExportError, ExportOptions
from orbitcal.export.product import (
    AffineForm,
    NetworkForm,
    ProductInfo,
    affine_part,
    is_exact_affine,
    layout,
)

__all__ = [
    "NS",
    "VERSION_RULE",
    "coefficient_values",
    "lin_name",
    "linear_postfix",
    "render_xtce",
]

NS = "http://www.omg.org/spec/XTCE/20180204"
_T = f"{{{NS}}}"

#: The one rule for versions across restarts (docs/yamcs.md), enforced by this file: every
#: coefficient is a local parameter with ``persistence="false"``.
VERSION_RULE = (
    "Versions across restarts: after every (re)start of Yamcs the coefficients are this file's "
    "version, whether or not the processor persists parameters; yamcs-push installs another "
    "version of the same layout until the next restart (MagCalibration raises an event when it "
    "computes with it); to keep a version across restarts, load its XTCE."
)


def coefficient_values(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> dict[str, float | int | str]:
    """Local parameter name → value: what the XTCE initialises and ``yamcs-push`` sets.

    The affine part's coefficients (``<SYS>_LIN_*``) feed the MathAlgorithms; for an affine
    method they equal the JavaScript's (``<SYS>_*``) but are kept apart so that both
    algorithms read a complete set.
    """
    sys_ = options.space_system
    out: dict[str, float | int | str] = {
        f"{sys_}_VERSION": info.version,
        f"{sys_}_SHA256": info.sha256,
        f"{sys_}_LAYOUT": layout(form),
    }
    for name, value in form.coefficients().items():
        out[f"{sys_}_{name}"] = value
    for name, value in affine_part(form).coefficients().items():
        out[f"{sys_}_LIN_{name}"] = value
    return out


def lin_name(cal_name: str) -> str:
    """The parameter a MathAlgorithm writes for calibrated axis ``cal_name`` (defined here)."""
    return cal_name.rsplit("/", 1)[-1] + "_LIN"


def _sub(parent: ET.Element, tag: str, **attrib: str) -> ET.Element:
    return ET.SubElement(parent, _T + tag, attrib)


def _postfix(op: ET.Element, items: list[tuple[str, str]]) -> None:
    for kind, value in items:
        if kind == "param":
            _sub(op, "ParameterInstanceRefOperand", parameterRef=value)
        elif kind == "value":
            e = _sub(op, "ValueOperand")
            e.text = value
        else:
            e = _sub(op, "Operator")
            e.text = value


def linear_postfix(
    axis: int, raw: tuple[str, str, str], hk: list[str], coef: str
) -> list[tuple[str, str]]:
    """Postfix of ``sum_j M[axis, j] * (raw_j - o_j - sum_m K[j, m] * hk_m)``.

    Operands push on a stack; a binary operator pops ``r`` then ``l`` and pushes ``l op r``
    (Yamcs ``MathOperationCalibratorFactory.getJavaExpression``).
    """
    items: list[tuple[str, str]] = []
    for j in range(3):
        items += [("param", raw[j]), ("param", f"{coef}O_{j}"), ("op", "-")]
        for m, name in enumerate(hk):
            items += [("param", f"{coef}K_{j}_{m}"), ("param", name), ("op", "*"), ("op", "-")]
        items += [("param", f"{coef}M_{axis}_{j}"), ("op", "*")]
        if j > 0:
            items.append(("op", "+"))
    return items


def render_xtce(form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions) -> bytes:
    """The SpaceSystem as UTF-8 XML bytes."""
    ET.register_namespace("xtce", NS)
    hk_params = [options.hk_parameter(c) for c in form.hk_names]
    _check_names_differ(options, hk_params)
    plain = [n for n in hk_params if not n.startswith("/")]
    if options.yamcs_inputs == "qualified" and plain:
        raise ExportError(
            "--yamcs-inputs qualified: every housekeeping input needs the mission's qualified "
            f"name (--hk-names COLUMN=/SYSTEM/NAME); not: {', '.join(plain)}",
            field="hk_names",
        )
    root = ET.Element(_T + "SpaceSystem", {"name": options.space_system})
    _describe(root, form, info, options)
    tm = _sub(root, "TelemetryMetaData")
    _parameter_types(tm)
    _parameters(tm, form, info, options, hk_params)
    _algorithms(tm, form, info, options, hk_params)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n").encode("utf-8")


def _check_names_differ(options: ExportOptions, hk_params: list[str]) -> None:
    """Raise when a raw, housekeeping or calibrated parameter name is given twice."""
    names = [*options.raw_names, *hk_params, *options.cal_names]
    names += [lin_name(n) for n in options.cal_names]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ExportError(
            f"parameter names must differ; {', '.join(repeated)} named twice "
            "(raw, housekeeping and calibrated names)",
            field="hk_names",
        )


def _describe(
    root: ET.Element, form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> None:
    """The SpaceSystem's LongDescription (what Yamcs keeps and shows: the product, what the
    affine part carries and loses, the version rule) and the Header with the same notes (Yamcs
    drops ``NoteSet``; other XTCE tools read it)."""
    carries = (
        "the affine part b_cal = M (b_raw - o - K hk) in the MathAlgorithms *_LIN"
        if isinstance(form, AffineForm)
        else "the network's first-order expansion about the centre of its training inputs "
        "in the MathAlgorithms *_LIN (the JavaScript algorithm carries the whole network)"
    )
    exact = is_exact_affine(form)
    lines = info.lines() + loss_lines(
        info, carries=carries, exact=exact, loss=options.loss, which="affine"
    )
    if options.loss is not None:
        lines.append(
            f"held-out RMS of the JavaScript algorithm (whole calibration): "
            f"{options.loss.full_rms_nt:.6g} nT"
        )
    desc = _sub(root, "LongDescription")
    desc.text = xml_text(
        "\n".join(
            [
                f"orbitcal magnetometer calibration of {info.spacecraft}, version {info.version} "
                f"({info.method}). The JavaScript algorithm MagCalibration carries the whole "
                "calibration; the MathAlgorithms *_LIN carry its affine part. Both compute only "
                "when every raw and housekeeping input has a value.",
                VERSION_RULE,
                *lines,
            ]
        )
    )
    header = _sub(
        root,
        "Header",
        version=str(info.version),
        date=xml_text(info.created_at),
        classification="NotClassified",
        validationStatus="Working",
    )
    notes = _sub(header, "NoteSet")
    for line in [VERSION_RULE, *lines]:
        _sub(notes, "Note").text = xml_text(line)


def _parameter_types(tm: ET.Element) -> None:
    """The parameter types: field [nT], housekeeping, coefficient, version, text."""
    types = _sub(tm, "ParameterTypeSet")
    field_t = _sub(types, "FloatParameterType", name="MagneticField_nT", sizeInBits="64")
    _sub(_sub(field_t, "UnitSet"), "Unit").text = "nT"
    _sub(types, "FloatParameterType", name="Housekeeping", sizeInBits="64")
    _sub(types, "FloatParameterType", name="Coefficient", sizeInBits="64")
    _sub(types, "IntegerParameterType", name="Version", sizeInBits="32", signed="false")
    _sub(types, "StringParameterType", name="Text")


def _parameters(
    tm: ET.Element,
    form: AffineForm | NetworkForm,
    info: ProductInfo,
    options: ExportOptions,
    hk_params: list[str],
) -> None:
    """The ParameterSet: raw and housekeeping inputs (``options.yamcs_inputs``: local or
    telemetered), calibrated and their affine parts (derived), the coefficients (local); names
    starting with ``/`` are the mission's own. ``persistence`` is written on the local
    parameters only, where Yamcs reads it (``persistParameters``), and is off: after a (re)start
    the coefficients are this file's (the version rule, docs/yamcs.md) and a replayed raw value
    does not come back."""
    params = _sub(tm, "ParameterSet")

    def param(name: str, type_ref: str, source: str, what: str, initial: str | None = None) -> None:
        if name.startswith("/"):
            return  # defined in the mission's MDB
        attrib = {"name": name, "parameterTypeRef": type_ref, "shortDescription": xml_text(what)}
        if initial is not None:
            attrib["initialValue"] = initial
        p = _sub(params, "Parameter", **attrib)
        if source == "local":
            _sub(p, "ParameterProperties", dataSource=source, persistence="false")
        else:
            _sub(p, "ParameterProperties", dataSource=source)

    inputs = "local" if options.yamcs_inputs == "local" else "telemetered"
    for axis, name in zip("XYZ", options.raw_names, strict=True):
        param(name, "MagneticField_nT", inputs, f"raw magnetometer {axis} [nT], sensor axes")
    for column, name in zip(form.hk_names, hk_params, strict=True):
        param(name, "Housekeeping", inputs, f"housekeeping {column} (its table unit)")
    exact = is_exact_affine(form)
    for axis, name in zip("XYZ", options.cal_names, strict=True):
        param(name, "MagneticField_nT", "derived", f"calibrated {axis} [nT]: {_whole(info)}")
        param(lin_name(name), "MagneticField_nT", "derived", _lin_says(axis, info, options, exact))
    values = coefficient_values(form, info, options)
    for name, value in values.items():
        what = _COEF_SAYS.get(name.removeprefix(options.space_system + "_"), "coefficient")
        if isinstance(value, str):
            param(name, "Text", "local", what, xml_text(value))
        elif isinstance(value, int):
            param(name, "Version", "local", what, str(value))
        else:
            param(name, "Coefficient", "local", what, f64(value))


_COEF_SAYS = {
    "VERSION": "calibration version the coefficients belong to (set last by yamcs-push)",
    "SHA256": "SHA-256 of the calibration document of these coefficients",
    "LAYOUT": "shape of the coefficient set; yamcs-push refuses another",
}


def _whole(info: ProductInfo) -> str:
    return f"the whole {info.method} calibration (equals orbitcal apply)"


def _lin_says(axis: str, info: ProductInfo, options: ExportOptions, exact: bool) -> str:
    """What ``<CAL>_LIN`` is, said where Yamcs shows it (its description)."""
    if exact:
        return f"calibrated {axis} [nT] by the affine MathAlgorithm: equals the whole calibration"
    off = (
        "not measured"
        if options.loss is None
        else f"held-out RMS {options.loss.affine_rms_nt:.3g} nT vs "
        f"{options.loss.full_rms_nt:.3g} nT, up to {options.loss.affine_max_abs_diff_nt:.3g} nT off"
    )
    return (
        f"affine part only of the {info.method} network [nT], NOT the calibration ({off}); "
        f"use the calibrated {axis}"
    )


def _algorithms(
    tm: ET.Element,
    form: AffineForm | NetworkForm,
    info: ProductInfo,
    options: ExportOptions,
    hk_params: list[str],
) -> None:
    """The AlgorithmSet: the JavaScript MagCalibration (the whole calibration; every input
    mandatory, so Yamcs runs it only once each has a value) and one MathAlgorithm per axis (its
    affine part), triggered by MagCalibration's output of that axis: a MathAlgorithm has no
    mandatory inputs and would read a missing one as 0."""
    sys_ = options.space_system
    algos = _sub(tm, "AlgorithmSet")
    custom = _sub(algos, "CustomAlgorithm", name="MagCalibration")
    _sub(custom, "LongDescription").text = (
        f"the whole {info.method} calibration, version {info.version}; runs once every input "
        "has a value; raises an event when it computes with coefficients of another version "
        "than this file's (set by yamcs-push), and refuses coefficients of another layout"
    )
    ins: list[tuple[str, str]] = list(zip(options.raw_names, INPUT_RAW, strict=True))
    ins += list(zip(hk_params, hk_inputs(len(hk_params)), strict=True))
    ins += [(f"{sys_}_VERSION", "version"), (f"{sys_}_LAYOUT", "layout")]
    ins += [(f"{sys_}_{coef}", coef) for coef in form.coefficients()]
    ancillary = _sub(custom, "AncillaryDataSet")
    for _, in_name in ins:
        _sub(ancillary, "AncillaryData", name="Yamcs:AlgorithmMandatoryInput").text = in_name
    text = _sub(custom, "AlgorithmText", language="JavaScript")
    text.text = algorithm_text(
        form,
        [f"orbitcal: {info.spacecraft} v{info.version} {info.method} sha256 {info.sha256}"],
        version=info.version,
        layout=layout(form),
        system=sys_,
    )
    inputs = _sub(custom, "InputSet")
    for name, in_name in ins:
        _sub(inputs, "InputParameterInstanceRef", parameterRef=name, inputName=in_name)
    outputs = _sub(custom, "OutputSet")
    for name, out_name in zip(options.cal_names, OUTPUTS, strict=True):
        _sub(outputs, "OutputParameterRef", parameterRef=name, outputName=out_name)
    triggers = _sub(custom, "TriggerSet")
    for name in options.raw_names:
        _sub(triggers, "OnParameterUpdateTrigger", parameterRef=name)

    for axis, name in enumerate(options.cal_names):
        algo = _sub(algos, "MathAlgorithm", name=f"{lin_name(name)}_ALGORITHM")
        op = _sub(algo, "MathOperation", outputParameterRef=lin_name(name))
        _postfix(op, linear_postfix(axis, options.raw_names, hk_params, f"{sys_}_LIN_"))
        trig = _sub(op, "TriggerSet")
        _sub(trig, "OnParameterUpdateTrigger", parameterRef=name)
