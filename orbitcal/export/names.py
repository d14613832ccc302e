"""One identifier policy for every name and text that enters an export (issue 44).

A telemetry column, a ``raw_names`` / ``cal_names`` / ``hk_names`` option and a document's
fields (spacecraft, method, times) all end up inside generated files that another program
parses: a C compiler, an XTCE/XML reader, the COSMOS configuration parser (whose files are ERB
templates), a JavaScript engine. Three rules, applied here and nowhere else:

1. **A name is checked against one grammar** that is a subset of every target's:
   :data:`NAME` (letters, digits, ``_`` and ``-``, starting with a letter or ``_``, at most
   :data:`NAME_MAX_CHARS`), which XTCE's ``NameType`` (``[^./:\\[\\] ]+``) and a COSMOS item name
   accept, or a qualified reference ``/SYSTEM/NAME`` of such names for the mission's own XTCE
   parameters. The default name of a housekeeping column (its upper-cased column name) is
   made to fit deterministically (:func:`default_hk_name`); names given as options are refused
   when they do not fit. No user name becomes a C or JavaScript identifier (the header and the
   algorithm use fixed identifiers); :func:`is_c_identifier` / :func:`is_js_identifier` check
   the fixed ones.
2. **The names of one export differ from each other and from the export's own names**
   (:func:`check_export_names`): raw, housekeeping and calibrated names, the ``*_LIN`` outputs
   and every coefficient parameter (``MAGCAL_M_0_0``, ``MAGCAL_VERSION``) for XTCE, the item
   names (last path element, case-insensitive: COSMOS upper-cases) for COSMOS.
3. **Text is escaped for its target before it is written** (:func:`c_comment`,
   :func:`c_string`, :func:`cosmos_comment`, :func:`js_comment`, :func:`xml_text`): outside
   printable ASCII (and the target's own delimiters) every character is written ``\\uXXXX``,
   so no text can end a comment, start a line, open an ERB tag or break the XML.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from orbitcal.export.errors import ExportError

__all__ = [
    "NAME",
    "NAME_MAX_CHARS",
    "QUALIFIED",
    "c_comment",
    "c_string",
    "check_export_names",
    "check_name",
    "cosmos_comment",
    "cosmos_token",
    "default_hk_name",
    "is_c_identifier",
    "is_cosmos_item",
    "is_js_identifier",
    "js_comment",
    "safe_text",
    "xml_text",
]

#: The longest parameter name [characters] (Yamcs and COSMOS take far longer ones; a bound).
NAME_MAX_CHARS = 128
#: A plain parameter name: a subset of XTCE ``NameType`` and of a COSMOS item name.
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*", re.ASCII)
#: A qualified reference to a parameter the mission's MDB defines (``/SYS/NAME``).
QUALIFIED = re.compile(r"(?:/[A-Za-z_][A-Za-z0-9_\-]*)+", re.ASCII)
_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*", re.ASCII)
_JS_IDENTIFIER = re.compile(r"[A-Za-z_$][A-Za-z0-9_$]*", re.ASCII)
_JS_RESERVED = frozenset(
    re.findall(
        r"\w+",
        "break case catch class const continue debugger default delete do else enum export "
        "extends false finally for function if implements import in instanceof interface let "
        "new null package private protected public return static super switch this throw true "
        "try typeof var void while with yield",
    )
)


def check_name(name: str, option: str, *, qualified: bool = True) -> str:
    """``name`` if it is a parameter name (or, with ``qualified``, a ``/SYS/NAME`` reference);
    else :class:`~orbitcal.export.options.ExportError` naming ``option``."""
    ok = NAME.fullmatch(name) or (qualified and QUALIFIED.fullmatch(name))
    if not ok or len(name) > NAME_MAX_CHARS:
        shown = safe_text(name[:60]) + ("..." if len(name) > 60 else "")
        raise ExportError(
            f"{option}: {shown!r} is not a parameter name (ASCII letters, digits, '_' or '-', "
            f"starting with a letter or '_', at most {NAME_MAX_CHARS} characters"
            + (", or a qualified /SYSTEM/NAME)" if qualified else ")"),
            field=option,
        )
    return name


def default_hk_name(column: str) -> str:
    """The parameter name of housekeeping column ``column`` when ``hk_names`` gives none: the
    column upper-cased, every run of characters outside ``[A-Z0-9-]`` replaced by one ``_``,
    no trailing ``_`` (COSMOS refuses ``__`` and a trailing ``_`` in item names), ``HK_`` in
    front when it would start with a digit or ``-`` (``HK`` when nothing is left), cut to
    :data:`NAME_MAX_CHARS`.

    Deterministic, so the same column always gets the same name; two columns that end with the
    same name are refused by :func:`check_export_names` (name them with ``hk_names``).
    """
    name = re.sub(r"[^A-Z0-9\-]+", "_", column.upper(), flags=re.ASCII)
    name = name[:NAME_MAX_CHARS].rstrip("_")
    if not name:
        return "HK"
    if not (name[0].isalpha() or name[0] == "_"):
        name = ("HK_" + name)[:NAME_MAX_CHARS].rstrip("_")
    return name


def is_cosmos_item(name: str) -> bool:
    """A COSMOS item name (openc3 ``ConfigParser.verify_parameter_naming``: no ``__``, no
    trailing ``_``) that is also a :data:`NAME`."""
    return bool(NAME.fullmatch(name)) and "__" not in name and not name.endswith("_")


def is_c_identifier(name: str) -> bool:
    return bool(_C_IDENTIFIER.fullmatch(name)) and not name.startswith("__")


def is_js_identifier(name: str) -> bool:
    return bool(_JS_IDENTIFIER.fullmatch(name)) and name not in _JS_RESERVED


def _where(kind: str, index: int, column: str | None) -> str:
    if column is not None:
        return f"hk column {safe_text(column[:60])!r} (hk_names)"
    return f"{kind}[{index}]"


def check_export_names(
    *,
    raw: Iterable[str],
    cal: Iterable[str],
    hk: Iterable[tuple[str, str]],
    target: str,
    own: Iterable[str] = (),
) -> None:
    """Raise :class:`~orbitcal.export.options.ExportError` when two names of one export are
    the same in ``target``'s eyes.

    ``hk`` pairs each housekeeping column with its parameter name; ``own`` lists the names the
    export defines itself (coefficient parameters, ``*_LIN`` outputs). ``target`` ``"cosmos"``
    compares item names (the last path element, case-insensitively); the others compare the
    names as written.
    """

    def key(name: str) -> str:
        return name.rsplit("/", 1)[-1].upper() if target == "cosmos" else name

    seen: dict[str, str] = {}
    entries: list[tuple[str, str]] = []
    entries += [(n, _where("raw_names", i, None)) for i, n in enumerate(raw)]
    entries += [(n, _where("hk_names", 0, c)) for c, n in hk]
    entries += [(n, _where("cal_names", i, None)) for i, n in enumerate(cal)]
    entries += [(n, f"the export's own parameter {n}") for n in own]
    for name, where in entries:
        k = key(name)
        if target == "cosmos" and not where.startswith("the export") and not is_cosmos_item(k):
            raise ExportError(
                f"cosmos export: {where} gives item {k!r}, which COSMOS refuses (an item name "
                "has no '__' and does not end with '_'); rename with raw_names, cal_names or "
                "hk_names",
                field=_field(where),
            )
        if k in seen:
            raise ExportError(
                f"{target} export: {k} named twice, by {seen[k]} and by {where}; every raw, "
                "housekeeping and calibrated name must differ from the others and from the "
                "export's own parameters (rename with raw_names, cal_names or hk_names)",
                field=_field(where),
            )
        seen[k] = where


def _field(where: str) -> str:
    if "hk column" in where:
        return "hk_names"
    return "names" if where.startswith("the export") else where.split("[")[0]


def safe_text(text: str, also: str = "") -> str:
    """``text`` with every character outside printable ASCII, and every one in ``also``,
    written as ``\\uXXXX`` (``\\UXXXXXXXX`` above the BMP)."""

    def esc(ch: str) -> str:
        o = ord(ch)
        return f"\\u{o:04x}" if o <= 0xFFFF else f"\\U{o:08x}"

    return "".join(ch if " " <= ch <= "~" and ch not in also else esc(ch) for ch in text)


def c_comment(text: str) -> str:
    """Text inside a C ``/* ... */`` comment line: no newline, no ``*`` (so no ``*/``, ``/*``)."""
    return safe_text(text, also="*")


def c_string(text: str) -> str:
    """The inside of a C string literal (``"..."``): ``"``, ``\\`` and ``?`` (trigraphs)
    escaped, every byte outside printable ASCII as a three-digit octal escape."""
    out = []
    for byte in text.encode("utf-8", "surrogatepass"):
        ch = chr(byte)
        if ch in '"\\?':
            out.append("\\" + ch)
        elif " " <= ch <= "~":
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return "".join(out)


def cosmos_comment(text: str) -> str:
    """Text after ``#`` in a COSMOS configuration file (an ERB template): one line, no ``%``
    (so no ``<%`` tag)."""
    return safe_text(text, also="%")


def cosmos_token(text: str) -> str:
    """One whitespace-free argument of a COSMOS keyword line: no space, quote, ``#`` or ``%``."""
    return safe_text(text, also=" \"'#%")


def js_comment(text: str) -> str:
    """Text after ``//`` in JavaScript: one line (no line terminator, U+2028/2029 included)."""
    return safe_text(text)


_XML_BAD = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    """Text or attribute value XML 1.0 can carry (ElementTree escapes ``<&>"``): characters
    XML forbids (controls, lone surrogates, U+FFFE/FFFF) written as ``\\uXXXX``."""
    return _XML_BAD.sub(lambda m: safe_text(m.group(0)), text)
