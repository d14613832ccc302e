"""GRACE-FO Level-1B RL04 ASCII files: the YAML header, then whitespace-separated records.

Every RL04 ASCII file (PO.DAAC, DOI 10.5067/GFJPL-L1B04) starts with a YAML document that ends at
the line ``# End of YAML header``. Its ``header.variables`` list names each column, in order, with
a ``comment`` such as ``5th column`` and its ``units``. This module reads that header and then the
records **by the names the header gives**: a file whose columns come in another order is read
correctly, and a file lacking a column the caller needs, or declaring it in another unit, is
refused with an :class:`~orbitcal.ingest.errors.IngestError` naming the file, line and field —
never misread by position.

Records are read in chunks (``pandas.read_csv`` with the C tokenizer), so a whole day of MAG1B
(172,800 records) or a month of them stays within a bounded memory.
"""

from __future__ import annotations

import gzip
import io
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import yaml

from orbitcal.ingest.errors import IngestError

__all__ = [
    "END_OF_HEADER",
    "L1BChunk",
    "L1BFile",
    "L1BVariable",
    "flag_bits",
]

#: The line that closes the YAML header of an RL04 ASCII file.
END_OF_HEADER = "# End of YAML header"

_ORDINAL = re.compile(r"^\s*(\d+)(?:st|nd|rd|th)\s+column\b", re.IGNORECASE)
_REST = re.compile(r"remaining portion", re.IGNORECASE)
_MAX_HEADER_LINES = 2000
#: The longest line (header or record) a reader accepts [bytes]. RL04 records are ~150 bytes; a
#: longer line (a decompression bomb in a ``.gz`` file, a file that is not L1B) is refused as it
#: streams past, before pandas' tokenizer or the YAML parser would buffer it whole.
MAX_LINE_BYTES = 64 * 1024


@dataclass(frozen=True)
class L1BVariable:
    """One column as the header declares it.

    Attributes
    ----------
    name : str
        The variable's name (``MfvX_RAW``, ``gps_time``, …).
    column : int
        0-based column in the records.
    units : str or None
        The declared unit (``microTesla``, ``m``, ``seconds``, …), None when the header gives none.
    rest_of_line : bool
        The column holds the entire remaining portion of each record (IHK1B ``sensorname``).
    """

    name: str
    column: int
    units: str | None
    rest_of_line: bool = False


@dataclass(frozen=True)
class L1BChunk:
    """Consecutive records of one file.

    Attributes
    ----------
    first_line : int
        1-based line of the chunk's first record in the file (header lines counted).
    columns : dict of str to ndarray, shape (n,)
        The requested variables by name.
    """

    first_line: int
    columns: dict[str, npt.NDArray[Any]]

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0


class _LineBounded(io.RawIOBase):
    """A byte stream that refuses a line longer than ``MAX_LINE_BYTES`` as it is read.

    The check runs on each block (``bytes.rfind`` in C), so what the stream expands to — a
    ``.gz`` file decompresses as it is read — is bounded per line, not only in bytes on disk.
    """

    def __init__(self, raw: IO[bytes], path: Path) -> None:
        self._raw = raw
        self._path = path
        self._run = 0  # bytes since the last line end

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        data = self._raw.read(len(buffer))
        n = len(data)
        buffer[:n] = data
        end = data.rfind(b"\n")
        self._run = self._run + n if end < 0 else n - end - 1
        if self._run > MAX_LINE_BYTES or (end >= 0 and _longest_line(data) > MAX_LINE_BYTES):
            raise IngestError(
                self._path,
                f"a line longer than {MAX_LINE_BYTES:,} bytes (after decompression): not an "
                "RL04 ASCII file (the limit MAX_LINE_BYTES bounds what a file expands to)",
            )
        return n

    def close(self) -> None:
        self._raw.close()
        super().close()


def _longest_line(data: bytes) -> int:
    """The longest run between line ends inside one block (only checked when it could exceed)."""
    if len(data) <= MAX_LINE_BYTES:
        return 0
    return max(map(len, data.split(b"\n")[1:-1]), default=0)


def _open_text(path: Path) -> IO[str]:
    raw: Any = gzip.open(path, "rb") if path.name.endswith(".gz") else path.open("rb")  # noqa: SIM115
    return io.TextIOWrapper(
        io.BufferedReader(_LineBounded(raw, path)), encoding="ascii", errors="strict"
    )


class _NoAliasLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` without anchors and aliases.

    An alias makes a node stand for another, so ten nested levels of ten aliases each describe
    10^10 nodes in a header of a kilobyte (a "billion laughs"): any walk over the document
    (``str()``, a copy, a comparison) then exhausts memory. RL04 headers use no aliases, so the
    first one is refused, naming its line.
    """

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None,
                None,
                f"a YAML alias (*{event.anchor}): RL04 headers use none, and aliases can expand "
                "a small header without bound",
                event.start_mark,
            )
        return super().compose_node(parent, index)


@dataclass(frozen=True)
class L1BFile:
    """A Level-1B RL04 ASCII file: its header and a chunked reader of its records.

    Build it with :meth:`open`. ``product`` is the product name (``MAG1B``, ``GNV1B``, …), taken
    from the file name (``MAG1B_2023-06-01_C_04.txt``) and checked against the header's title.
    """

    path: Path
    product: str
    date: str
    satellite: str
    header_lines: int
    num_records: int | None
    variables: tuple[L1BVariable, ...]
    attributes: dict[str, Any] = field(default_factory=dict)
    units_by_name: dict[str, str | None] = field(default_factory=dict)

    #: ``PROD_YYYY-MM-DD_S_RL.txt`` (optionally ``.gz``).
    NAME_PATTERN = re.compile(
        r"^(?P<product>[A-Z0-9]{3}1B)_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rl>\d{2})\.txt(\.gz)?$"
    )

    @classmethod
    def parse_name(cls, path: str | Path) -> tuple[str, str, str] | None:
        """``(product, date, satellite)`` from a standard file name, or None."""
        m = cls.NAME_PATTERN.match(Path(path).name)
        return None if m is None else (m["product"], m["date"], m["sat"])

    @classmethod
    def open(cls, path: str | Path) -> L1BFile:
        """Read and check the YAML header of ``path``.

        Raises
        ------
        IngestError
            The file is missing, has no YAML header, the header is not YAML, or its variables do
            not describe consecutive columns.
        """
        p = Path(path)
        parsed = cls.parse_name(p)
        if parsed is None:
            raise IngestError(
                p, "not a GRACE-FO Level-1B file name (expected e.g. MAG1B_2023-06-01_C_04.txt)"
            )
        product, date, sat = parsed
        if not p.is_file():
            raise IngestError(p, "no such file")
        lines: list[str] = []
        try:
            with _open_text(p) as fh:
                for line in fh:
                    if line.startswith(END_OF_HEADER):
                        break
                    lines.append(line)
                    if len(lines) > _MAX_HEADER_LINES:
                        raise IngestError(p, f"no '{END_OF_HEADER}' line in the first lines")
                else:
                    raise IngestError(p, f"no '{END_OF_HEADER}' line: not an RL04 ASCII file")
        except UnicodeDecodeError as exc:
            raise IngestError(p, f"not ASCII text ({exc.reason})") from exc
        try:
            doc = yaml.load("".join(lines), Loader=_NoAliasLoader)  # a SafeLoader
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line_no = None if mark is None else int(mark.line) + 1
            raise IngestError(p, f"the YAML header does not parse: {exc}", line=line_no) from exc
        header = doc.get("header") if isinstance(doc, dict) else None
        if not isinstance(header, dict) or not isinstance(header.get("variables"), list):
            raise IngestError(p, "the YAML header has no header.variables list", field="variables")
        variables = _variables(p, header["variables"])
        attrs: dict[str, Any] = {}
        for key in ("global_attributes", "non-standard_attributes"):
            block = header.get(key)
            if isinstance(block, dict):
                attrs.update(block)
        platform = attrs.get("platform", "")
        if not isinstance(platform, str | int | float):
            raise IngestError(p, "the header's platform is not a text value", field="platform")
        platform = str(platform)
        if platform and not platform.endswith(sat):
            raise IngestError(
                p,
                f"the header's platform is {platform!r} but the name says {sat}",
                field="platform",
            )
        dims = header.get("dimensions")
        num = dims.get("num_records") if isinstance(dims, dict) else None
        return cls(
            path=p,
            product=product,
            date=date,
            satellite=sat,
            header_lines=len(lines) + 1,
            num_records=int(num) if isinstance(num, int) else None,
            variables=variables,
            attributes=attrs,
            units_by_name={v.name: v.units for v in variables},
        )

    def variable(self, name: str, *, units: Sequence[str] | None = None) -> L1BVariable:
        """The header's declaration of ``name``; checks its unit when ``units`` are given.

        Raises
        ------
        IngestError
            The header declares no such variable (a foreign layout), or another unit.
        """
        for v in self.variables:
            if v.name == name:
                if units is not None and (v.units or "") not in units:
                    raise IngestError(
                        self.path,
                        f"{self.product} declares {name} in {v.units!r}, expected "
                        + " or ".join(repr(u) for u in units),
                        field=name,
                    )
                return v
        names = ", ".join(v.name for v in self.variables)
        raise IngestError(
            self.path,
            f"the {self.product} header declares no column {name!r} (it has: {names}): "
            "not the RL04 layout this reader knows",
            field=name,
        )

    def chunks(
        self,
        names: Sequence[str],
        *,
        text: Sequence[str] = (),
        chunk_rows: int = 100_000,
    ) -> Iterator[L1BChunk]:
        """The records, ``chunk_rows`` at a time, as arrays of the named variables.

        Parameters
        ----------
        names : sequence of str
            Variables to read as numbers (float64, or int64 for integer columns).
        text : sequence of str
            Variables to read as text (``GRACEFO_id``, ``time_ref``, ``sensortype``, …).
        chunk_rows : int
            Records per chunk.

        Raises
        ------
        IngestError
            A record has more or fewer fields than the header declares (a truncated or foreign
            file), or a numeric field does not parse; the line and field are named.
        """
        wanted = {self.variable(n).column: n for n in [*names, *text]}
        n_cols = len(self.variables)
        dtypes: dict[int, Any] = {self.variable(n).column: str for n in text}
        try:
            fh = _open_text(self.path)
        except OSError as exc:
            raise IngestError(self.path, f"cannot read: {exc.strerror}") from exc
        with fh:
            reader = pd.read_csv(
                fh,
                sep=r"\s+",
                header=None,
                names=list(range(n_cols)),
                dtype=dtypes,
                skiprows=self.header_lines,
                chunksize=chunk_rows,
                engine="c",
                na_filter=True,
                keep_default_na=False,
                na_values=[""],
            )
            line = self.header_lines + 1
            try:
                for df in reader:
                    yield self._checked_chunk(df, wanted, names, line)
                    line += len(df)
            except pd.errors.ParserError as exc:
                m = re.search(r"line (\d+), saw (\d+)", str(exc))
                bad = int(m[1]) if m else None
                saw = f" ({m[2]} fields)" if m else ""
                raise IngestError(
                    self.path,
                    f"a record has more fields than the header's {n_cols} columns{saw}",
                    line=bad,
                ) from exc
            except UnicodeDecodeError as exc:
                raise IngestError(self.path, f"not ASCII text ({exc.reason})", line=line) from exc

    def _checked_chunk(
        self,
        df: pd.DataFrame,
        wanted: dict[int, str],
        numeric: Sequence[str],
        first_line: int,
    ) -> L1BChunk:
        df = df[sorted(wanted)]
        missing = df.isna().to_numpy()
        if missing.any():
            row, col = np.argwhere(missing)[0]
            name = wanted[int(df.columns[col])]
            raise IngestError(
                self.path,
                f"the record ends before the field (fewer than the header's "
                f"{len(self.variables)} columns): a truncated file?",
                line=first_line + int(row),
                field=name,
            )
        cols: dict[str, npt.NDArray[Any]] = {}
        for c, name in wanted.items():
            values = df[c].to_numpy()
            if name in numeric and values.dtype.kind not in "iuf":
                converted = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=np.float64)
                bad = np.flatnonzero(~np.isfinite(converted))
                row = int(bad[0]) if bad.size else 0
                raise IngestError(
                    self.path,
                    f"{str(df[c].iloc[row])!r} is not a number",
                    line=first_line + row,
                    field=name,
                )
            cols[name] = values
        return L1BChunk(first_line=first_line, columns=cols)


def _variables(path: Path, items: list[Any]) -> tuple[L1BVariable, ...]:
    out: list[L1BVariable] = []
    for i, item in enumerate(items):
        if not isinstance(item, dict) or len(item) != 1:
            raise IngestError(path, f"header variable #{i + 1} is not a 'name: {{...}}' entry")
        name, spec = next(iter(item.items()))
        spec = spec if isinstance(spec, dict) else {}
        comment = str(spec.get("comment", ""))
        m = _ORDINAL.match(comment)
        rest = bool(_REST.search(comment))
        if m:
            column = int(m[1]) - 1
        elif rest:
            column = len(out)
        else:
            raise IngestError(
                path, f"header variable {name!r} has no 'Nth column' comment", field=str(name)
            )
        units = spec.get("units")
        out.append(L1BVariable(str(name), column, None if units is None else str(units), rest))
    columns = sorted(v.column for v in out)
    if columns != list(range(len(out))):
        raise IngestError(
            path,
            f"the header's columns are not 1..{len(out)} each once "
            f"(got {[c + 1 for c in columns]})",
            field="variables",
        )
    return tuple(sorted(out, key=lambda v: v.column))


def flag_bits(flags_as_read: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Quality flags written as 8 binary digits (``00000010``), read as decimal → their bits.

    RL04 ASCII writes ``qualflg`` as a string of binary digits, bit 0 rightmost; read as a
    number, ``00000010`` is ten. This turns those numbers back into the integer whose bits they
    spell (ten → 2).
    """
    v = np.asarray(flags_as_read, dtype=np.int64)
    out = np.zeros_like(v)
    for k in range(8):
        digit = (v // 10**k) % 10
        out |= (digit & 1) << k
    return out
