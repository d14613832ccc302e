"""Names that become code (issue 44, classes 1 and 2): the identifier policy of
``orbitcal/export/names.py`` against arbitrary Unicode.

A property test per format feeds arbitrary housekeeping column names (every Unicode category,
lone surrogates included), spacecraft ids and ``raw_names`` / ``cal_names`` / ``hk_names``
options through :func:`orbitcal.export.export` and hands each result to its real consumer:

* ``c-header``: compiled with ``cc -std=c99 -Wall -Werror -pedantic`` and run (the string
  macros read back byte for byte, the table's CRC holds); the code with comments removed by the
  compiler's own preprocessor (``cc -fpreprocessed -E``) equals that of a header with harmless
  names, apart from the four string macros;
* ``xtce``: parsed, valid against the XTCE 1.2 schema, defines exactly the expected parameters
  (nothing injected, nothing twice) and every reference resolves;
* ``javascript`` (the XTCE's ``CustomAlgorithm``): run by ``node`` as Yamcs binds it, outputs
  equal :func:`orbitcal.export.evaluate.evaluate`; without its comment lines the text equals
  that of harmless names;
* ``cosmos``: no ERB tag but the variable references, processed by ``openc3``'s
  ``PacketConfig``: the packet gains exactly the three calibrated items, whose values equal
  ``evaluate``.

An export either succeeds and passes, or is refused with a one-line ``ExportError`` naming the
option. The names tried per format are counted and printed at the end of the module (stderr).
"""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_consumers import NS, run_yamcs_javascript, validate_xtce, xtce_schema, xtce_values
from hypothesis import example, given, settings
from hypothesis import strategies as st

from orbitcal.calibrate.errors import DocumentError
from orbitcal.export import ExportError, ExportOptions, calibration_form, export
from orbitcal.export.evaluate import evaluate
from orbitcal.export.names import (
    c_comment,
    c_string,
    check_name,
    cosmos_comment,
    default_hk_name,
    is_c_identifier,
    is_js_identifier,
    js_comment,
    xml_text,
)
from orbitcal.export.options import parse_hk_names, parse_names

#: Names tried per format (printed at the end of the module).
TRIED: Counter[str] = Counter()
REFUSED: Counter[str] = Counter()
MADE: Counter[str] = Counter()

#: The columns of issue 44's report, and other names that once broke an export.
ISSUE_COLUMNS = [
    'hk_a*/ int ORBITCAL_INJECTED_A; /*"<]]>&',
    "hk_b\n  ITEM ORBITCAL_INJECTED_B 0 0 DERIVED",
]
HOSTILE = [
    "hk_c\n#error injected",
    "hk_d<%= `id` %>",
    "hk_e\u2028cal_x.value = 0;",
    "hk_f\x00\ud800\uffff",
    "hk_g\\",
    "hk_h??/",
]

#: Every code point (lone surrogates too: the escaping functions take them).
_ANY_CHAR = st.characters(codec=None, exclude_categories=())
#: Every code point UTF-8 can carry: a lone surrogate makes the whole document unhashable (a
#: DocumentError before any name is looked at), so the examples above carry those.
NAME_TEXT = st.text(st.characters(codec="utf-8"), min_size=1, max_size=24)


@pytest.fixture(scope="module", autouse=True)
def _report_counts(request: pytest.FixtureRequest) -> Iterator[None]:
    yield
    rows = ", ".join(
        f"{fmt}: {TRIED[fmt]} names tried, {MADE[fmt]} exports made and consumed, "
        f"{REFUSED[fmt]} refused"
        for fmt in sorted(TRIED)
    )
    line = f"issue 44 names property test: {rows}"
    capture = request.config.pluginmanager.getplugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
        print("\n" + line, file=sys.stderr)


def _doc(columns: list[str], spacecraft: str = "sat-1") -> dict[str, Any]:
    k = len(columns)
    rng = np.random.default_rng(44)
    M = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    return {
        "spacecraft": spacecraft,
        "version": 3,
        "method": "linear-hk",
        "created_at": "2026-11-28T00:00:00Z",
        "reference_field": "IGRF-14",
        "data": {"start": "2026-11-01T00:00:00Z", "end": "2026-11-02T00:00:00Z"},
        "metrics": {"holdout_rms_nt": 1.5},
        "model": {
            "M": M.tolist(),
            "o": [12.5, -7.25, 3.0],
            "K": (0.5 * rng.standard_normal((3, k))).tolist(),
            "hk_names": list(columns),
        },
    }


def _options(fmt: str, raw: str | None, cal: str | None, hk: str | None) -> ExportOptions:
    from orbitcal.export import DEFAULT_CAL_NAMES, DEFAULT_RAW_NAMES

    return ExportOptions(
        format=fmt,
        raw_names=parse_names(raw, DEFAULT_RAW_NAMES, "raw_names"),
        cal_names=parse_names(cal, DEFAULT_CAL_NAMES, "cal_names"),
        hk_names=parse_hk_names(hk, "hk_names"),
    )


def _try_export(
    fmt: str, columns: list[str], raw: str | None, cal: str | None, hk: str | None, sc: str
) -> tuple[Any, ExportOptions] | None:
    """The export, or ``None`` when refused with a one-line error naming the option: an
    ExportError, or a DocumentError for a document that is not plain JSON (a lone surrogate has
    no UTF-8 form, so the document has no SHA-256)."""
    TRIED[fmt] += len(columns) + sum(x is not None for x in (raw, cal, hk)) + 1
    doc = _doc(columns, sc)
    try:
        options = _options(fmt, raw, cal, hk)
        made = export(doc, options)
        MADE[fmt] += 1
        return made, options
    except ExportError as exc:
        REFUSED[fmt] += 1
        assert "\n" not in str(exc) and exc.field, str(exc)
        return None
    except DocumentError as exc:
        REFUSED[fmt] += 1
        assert "\n" not in str(exc) and "surrogates not allowed" in str(exc), str(exc)
        return None


def _inputs(k: int) -> tuple[np.ndarray, np.ndarray | None]:
    rng = np.random.default_rng(7)
    raw = rng.uniform(-40000, 40000, (4, 3))
    return raw, (rng.uniform(-5, 30, (4, k)) if k else None)


def _harmless(k: int) -> list[str]:
    return [f"hk_{j}" for j in range(k)]


# ------------------------------------------------------------------ strategies

columns_st = st.lists(NAME_TEXT, min_size=0, max_size=3, unique=True)
_VALID = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,6}", fullmatch=True)
#: Mostly no option or valid names (so that most exports are made and consumed), some hostile.
option_st = st.one_of(
    st.none(),
    st.none(),
    st.none(),
    st.lists(_VALID, min_size=3, max_size=3, unique_by=str.upper).map(",".join),
    st.lists(_VALID, min_size=3, max_size=3, unique_by=str.upper).map(",".join),
    st.lists(NAME_TEXT, min_size=3, max_size=3).map(",".join),
)


@st.composite
def hk_option_st(draw: Any, columns: list[str]) -> str | None:
    """``hk_names``: nothing, or some columns renamed to valid or arbitrary names."""
    if not columns or draw(st.booleans()):
        return None
    named = draw(st.lists(st.sampled_from(columns), min_size=1, unique=True))
    return ",".join(f"{c}={draw(st.one_of(_VALID, _VALID, NAME_TEXT))}" for c in named)


@st.composite
def case_st(draw: Any) -> tuple[list[str], str | None, str | None, str | None, str]:
    columns = draw(columns_st)
    return (
        columns,
        draw(option_st),
        draw(option_st),
        draw(hk_option_st(columns)),
        draw(st.one_of(_VALID, NAME_TEXT)),
    )


# ------------------------------------------------------------------ C header

_STRING_MACROS = ("SPACECRAFT", "METHOD", "SHA256", "VALIDITY_START")
_MAIN = r"""
#include <stdio.h>
#include "orbitcal_magcal.h"
#define SHOW(s) (printf("%u:", (unsigned)(sizeof(s) - 1)), fwrite(s, 1, sizeof(s) - 1, stdout))
int main(void)
{
    SHOW(ORBITCAL_MAGCAL_SPACECRAFT);
    SHOW(ORBITCAL_MAGCAL_METHOD);
    SHOW(ORBITCAL_MAGCAL_SHA256);
    SHOW(ORBITCAL_MAGCAL_VALIDITY_START);
    printf("%d %d", orbitcal_magcal_table_ok(), ORBITCAL_MAGCAL_N_HK);
    return 0;
}
"""


def _shown(out: bytes) -> list[bytes]:
    """The four strings (``length:bytes`` each) and the last line the program printed."""
    fields = []
    for _ in _STRING_MACROS:
        n, _, out = out.partition(b":")
        fields.append(out[: int(n)])
        out = out[int(n) :]
    return [*fields, out]


def _c_code(header: bytes, tmp: Path) -> list[str]:
    """The header's code with comments removed by the compiler, string macros left out."""
    path = tmp / "strip.h"
    path.write_bytes(header)
    cc = shutil.which("cc")
    assert cc is not None
    out = subprocess.run(
        [cc, "-fpreprocessed", "-dD", "-E", "-P", str(path)],
        capture_output=True,
        check=True,
    ).stdout.decode("latin-1")
    skip = tuple(f"#define ORBITCAL_MAGCAL_{m} " for m in _STRING_MACROS)
    return [ln for ln in out.splitlines() if ln.strip() and not ln.startswith(skip)]


def _compile_and_run(header: bytes, tmp: Path) -> list[bytes]:
    cc = shutil.which("cc")
    assert cc is not None
    (tmp / "orbitcal_magcal.h").write_bytes(header)
    (tmp / "main.c").write_text(_MAIN)
    exe = tmp / "main"
    build = subprocess.run(
        [cc, "-std=c99", "-Wall", "-Werror", "-pedantic", "-o", str(exe), str(tmp / "main.c")],
        capture_output=True,
    )
    assert build.returncode == 0, build.stderr.decode(errors="replace")[:2000]
    return _shown(subprocess.run([str(exe)], capture_output=True, check=True).stdout)


@settings(max_examples=100)
@given(case=case_st())
@example(case=(ISSUE_COLUMNS, None, None, None, "sat-1"))
@example(case=(HOSTILE[:3], None, None, None, 'x*/ int INJ; /*"\n#error e'))
@example(case=(HOSTILE[3:], None, None, None, "??/\\\ud800"))
def test_c_header_compiles_with_any_names(
    case: tuple[list[str], str | None, str | None, str | None, str],
) -> None:
    columns, raw, cal, hk, sc = case
    done = _try_export("c-header", columns, raw, cal, hk, sc)
    if done is None:
        return
    result, _ = done
    assert result.content is not None
    with tempfile.TemporaryDirectory() as tmp:
        out = _compile_and_run(result.content, Path(tmp))
        doc = _doc(columns, sc)
        assert out[0] == sc.encode("utf-8", "surrogatepass")
        assert out[4] == f"1 {len(columns)}".encode()
        base = export(_doc(_harmless(len(columns))), ExportOptions(format="c-header"))
        assert base.content is not None
        assert _c_code(result.content, Path(tmp)) == _c_code(base.content, Path(tmp)), doc


# ------------------------------------------------------------------ XTCE and its JavaScript

_SCHEMA: list[Any] = []


def _expected_parameters(root: ET.Element, options: ExportOptions, columns: list[str]) -> None:
    names = [p.get("name") for p in root.iterfind(".//x:ParameterSet/x:Parameter", NS)]
    assert len(names) == len(set(names)), "a parameter defined twice"
    hk = [options.hk_parameter(c) for c in columns]
    local = [n for n in (*options.raw_names, *hk, *options.cal_names) if not n.startswith("/")]
    local += [n.rsplit("/", 1)[-1] + "_LIN" for n in options.cal_names]
    coefs = {n for n in names if n is not None and n.startswith("MAGCAL_")}
    assert set(names) == set(local) | coefs
    for n in names:
        assert n is not None and check_name(n, "parameter") == n
    defined = set(names)
    for e in root.iter():
        for attr in ("parameterRef", "outputParameterRef"):
            ref = e.get(attr)
            if ref is not None:
                assert ref in defined or ref.startswith("/"), ref


def _js_code(text: str) -> list[str]:
    """The script without its comments and without the one literal that carries the layout's
    column names (a JSON string: ``var FILE_LAYOUT = "...";``)."""
    lines = [ln for ln in text.splitlines() if not ln.startswith("//")]
    return [ln for ln in lines if not ln.startswith("var FILE_LAYOUT = ")]


@settings(max_examples=100)
@given(case=case_st())
@example(case=(ISSUE_COLUMNS, None, None, None, "sat-1"))
@example(case=(HOSTILE[:3], None, None, None, "x\n// y\u2028z"))
@example(case=(HOSTILE[3:], None, None, None, "\x01\ud800]]>"))
@example(case=(["hk_x"], "MAGCAL_M_0_0,B,C", None, None, "s"))
@example(case=(["hk_x"], None, "/A/X,/B/X,/C/X", None, "s"))
def test_xtce_and_javascript_with_any_names(
    case: tuple[list[str], str | None, str | None, str | None, str],
) -> None:
    columns, raw, cal, hk, sc = case
    done = _try_export("xtce", columns, raw, cal, hk, sc)
    TRIED["javascript"] += len(columns) + 1
    if done is None:
        REFUSED["javascript"] += 1
        return
    MADE["javascript"] += 1
    result, options = done
    assert result.content is not None
    if not _SCHEMA:
        _SCHEMA.append(xtce_schema())
    assert validate_xtce(result.content, _SCHEMA[0]) == []
    root = ET.fromstring(result.content)
    _expected_parameters(root, options, columns)
    # JavaScript: the text without its comment lines is the same as for harmless names
    text = root.findtext(".//x:CustomAlgorithm/x:AlgorithmText", namespaces=NS)
    base = ET.fromstring(export(_doc(_harmless(len(columns))), ExportOptions(format="xtce")).body())
    base_text = base.findtext(".//x:CustomAlgorithm/x:AlgorithmText", namespaces=NS)
    assert text is not None and base_text is not None
    assert _js_code(text) == _js_code(base_text)
    raw_nt, x_hk = _inputs(len(columns))
    hk_params = [options.hk_parameter(c) for c in columns]
    values = xtce_values(root, options.raw_names, raw_nt, hk_params, x_hk)
    got = run_yamcs_javascript(root, values, len(raw_nt))
    want = evaluate(calibration_form(_doc(columns, sc)), raw_nt, x_hk)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


# ------------------------------------------------------------------ COSMOS


def _cosmos_packet(files: dict[str, bytes], raw: list[str], hk: list[str]) -> Any:
    """The mission packet INST MAG after openc3 processed the fragment (ERB step as the plugin
    install does for ``<%= name %>``)."""
    from openc3.packets.packet_config import PacketConfig

    text = files["targets/MAGCAL/cmd_tlm/magcal_tlm.txt"].decode()
    leftover = re.sub(r"<%= magcal_\w+ %>", "", text)
    assert "<%" not in leftover and "%>" not in leftover, "an ERB tag besides the variables"
    variables = json.loads(files["vars.json"])
    rendered = re.sub(r"<%=\s*(\w+)\s*%>", lambda m: variables[m.group(1)], text)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "mission.txt").write_text(
            'TELEMETRY INST MAG BIG_ENDIAN "magnetometer packet"\n'
            + "".join(f'  APPEND_ITEM {n} 64 FLOAT "input"\n' for n in [*raw, *hk])
        )
        (d / "magcal.txt").write_text(rendered)
        lib = d / "lib"
        lib.mkdir()
        (lib / "mag_calibration.py").write_bytes(files["targets/MAGCAL/lib/mag_calibration.py"])
        sys.path.insert(0, str(lib))
        sys.modules.pop("mag_calibration", None)
        try:
            config = PacketConfig()
            config.process_file(str(d / "mission.txt"), "INST")
            before = set(config.telemetry["INST"]["MAG"].items)
            config.process_file(str(d / "magcal.txt"), "INST")
            return config.telemetry["INST"]["MAG"], before
        finally:
            sys.path.remove(str(lib))


@settings(max_examples=100)
@given(case=case_st())
@example(case=(ISSUE_COLUMNS, None, None, None, "sat-1"))
@example(case=(HOSTILE[:3], None, None, None, "x\n  ITEM INJ 0 0 DERIVED"))
@example(case=(HOSTILE[3:], None, None, None, "<%= `id` %>"))
@example(case=(["hk_x"], "/A/X,/B/X,/C/X", None, None, "s"))
@example(case=(["hk_x"], "q,b,c", "Q,B2,C2", None, "s"))
def test_cosmos_with_any_names(
    case: tuple[list[str], str | None, str | None, str | None, str],
) -> None:
    columns, raw, cal, hk, sc = case
    done = _try_export("cosmos", columns, raw, cal, hk, sc)
    if done is None:
        return
    result, options = done
    assert result.files is not None
    raw_items = [n.rsplit("/", 1)[-1] for n in options.raw_names]
    hk_items = [options.hk_parameter(c).rsplit("/", 1)[-1] for c in columns]
    cal_items = [n.rsplit("/", 1)[-1].upper() for n in options.cal_names]
    packet, before = _cosmos_packet(result.files, raw_items, hk_items)
    assert set(packet.items) - before == set(cal_items), "items besides the three calibrated"
    raw_nt, x_hk = _inputs(len(columns))
    want = evaluate(calibration_form(_doc(columns, sc)), raw_nt, x_hk)
    for k in range(len(raw_nt)):
        for j, name in enumerate(raw_items):
            packet.write(name, float(raw_nt[k, j]))
        for j, name in enumerate(hk_items):
            assert x_hk is not None
            packet.write(name, float(x_hk[k, j]))
        got = [packet.read(n) for n in cal_items]
        np.testing.assert_allclose(got, want[k], rtol=0, atol=1e-6)


# ------------------------------------------------------------------ the policy itself


@given(column=NAME_TEXT)
def test_default_hk_name_is_a_name_in_every_grammar(column: str) -> None:
    name = default_hk_name(column)
    assert check_name(name, "hk") == name
    assert default_hk_name(column) == name  # deterministic
    if "-" not in name and not name.startswith("__"):
        assert is_c_identifier(name) and is_js_identifier(name)


@given(text=st.text(_ANY_CHAR, max_size=40))
def test_escaped_text_cannot_leave_its_place(text: str) -> None:
    for escaped in (c_comment(text), js_comment(text), cosmos_comment(text)):
        assert escaped.isascii() and escaped.isprintable()
        assert "\n" not in escaped and "\r" not in escaped
    assert "*" not in c_comment(text)
    assert "%" not in cosmos_comment(text)
    literal = c_string(text)
    assert literal.isascii() and '"' not in literal.replace('\\"', "")
    assert "??" not in literal
    xml = xml_text(text)
    xml.encode("utf-8")  # no lone surrogate left
    assert not re.search("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]", xml)


@pytest.mark.parametrize(
    "name",
    ["A\n", "A B", "é", "١٢", "A*/", "<%=x%>", "a" * 129, "/A/", "A/B", "", "1A", "A.B"],
)
def test_names_outside_the_grammar_are_refused(name: str) -> None:
    with pytest.raises(ExportError, match="is not a parameter name") as err:
        ExportOptions(format="xtce", raw_names=(name, "B", "C"))
    assert "\n" not in str(err.value) and err.value.field == "names"


@pytest.mark.parametrize(
    ("fmt", "kwargs", "says"),
    [
        ("xtce", {"raw_names": ("MAGCAL_M_0_0", "B", "C")}, "MAGCAL_M_0_0 named twice"),
        ("xtce", {"raw_names": ("MAG_X_CAL_LIN", "B", "C")}, "MAG_X_CAL_LIN named twice"),
        ("xtce", {"cal_names": ("/A/X", "/B/X", "/C/X")}, "X_LIN named twice"),
        ("cosmos", {"raw_names": ("/A/X", "/B/X", "/C/X")}, "X named twice"),
        ("cosmos", {"raw_names": ("x", "B", "C"), "cal_names": ("X", "Y", "Z")}, "named twice"),
        ("c-header", {"hk_names": {"hk_a": "MAG_X_RAW"}}, "MAG_X_RAW named twice"),
        ("xtce", {}, "HK_A named twice"),  # hk_a* and hk_a? both default to HK_A
    ],
)
def test_names_of_one_export_must_differ(fmt: str, kwargs: dict[str, Any], says: str) -> None:
    columns = ["hk_a*", "hk_a?"] if not kwargs else ["hk_a"]
    with pytest.raises(ExportError, match=re.escape(says)) as err:
        export(_doc(columns), ExportOptions(format=fmt, **kwargs))
    assert "\n" not in str(err.value)
    if not kwargs:
        assert "hk_names" in str(err.value) and "hk_a*" in str(err.value)
