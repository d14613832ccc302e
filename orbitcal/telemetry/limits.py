"""Limits on untrusted uploads, and the JSON structure scan that enforces them before parsing."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orbitcal.errors import LimitExceededError

__all__ = ["DEFAULT_LIMITS", "ParseLimits", "json_scan"]


@dataclass(frozen=True)
class ParseLimits:
    """Size limits every reader enforces before a native parser (orjson, pyarrow, pandas) runs.

    A table beyond a limit raises :class:`~orbitcal.errors.LimitExceededError` (HTTP 413) naming
    the limit; the limits are documented in ``docs/reliability.md``. Bytes are bounded before
    this point (the service's body limit applies to the *decompressed* body).

    Attributes
    ----------
    max_rows : int
        Data rows (CSV lines, NDJSON lines, JSON elements, Parquet rows from the file's metadata,
        CCSDS packets).
    max_columns : int
        Columns of a table (contract columns plus ``hk_*`` channels and ignored ones).
    max_cells : int
        Rows × columns after expansion (Parquet from its metadata; JSON: values in the body).
    max_json_depth : int
        Nesting depth of ``[`` / ``{`` in JSON and in each NDJSON line (a record is depth 1).
    max_name_chars : int
        Length of a column name [characters].
    max_string_chars : int
        Length of one text cell (times, text housekeeping) [characters].
    max_decoded_bytes : int
        Parquet: uncompressed size of the column data, from the file's metadata [bytes].
    """

    max_rows: int = 1_000_000
    max_columns: int = 256
    max_cells: int = 16_000_000
    max_json_depth: int = 8
    max_name_chars: int = 128
    max_string_chars: int = 4096
    max_decoded_bytes: int = 512 * 2**20


#: The limits the readers and the service use unless told otherwise.
DEFAULT_LIMITS = ParseLimits()


def _limit(what: str, value: int | float, name: str, limit: int | float) -> LimitExceededError:
    return LimitExceededError(
        f"{what} ({value:,}) exceeds the limit {name} = {limit:,}", limit_name=name, limit=limit
    )


_SCAN_CHUNK = 1 << 20
#: Bytes the JSON scan looks at: " \\ [ { ] } line ends (LF, CR), comma and colon.
_SCAN_EVENTS = np.zeros(256, dtype=bool)
_SCAN_EVENTS[[34, 92, 91, 123, 93, 125, 10, 13, 44, 58]] = True


def json_scan(data: bytes, *, per_line: bool) -> tuple[int, int, int, int]:
    """Structure of a JSON (or NDJSON) body without parsing it.

    Returns ``(max_depth, at_byte, commas, colons)``.

    A vectorised pass over the raw bytes (1 MiB at a time, only the structural bytes kept):
    quotes not escaped by an odd run of backslashes toggle "inside a string" (reset at each
    line end, LF or CR, where no valid JSON string can continue); ``[``/``{`` and ``]``/``}``
    outside strings move the depth. For NDJSON (``per_line``) the depth counts from each line's
    start. Up to the first syntax error a parser would stop at, this is the parser's own view,
    so a body that passes a depth check here cannot drive a parser deeper. ``commas`` (outside
    strings) bounds the number of values; ``colons`` (outside strings) is the number of object
    keys, so a parser that keeps fewer keys dropped a repeated one.
    """
    a_all = np.frombuffer(data, dtype=np.uint8)
    depth = 0  # depth at the end of the previous chunk
    line_base = 0  # depth at the start of the current line (NDJSON)
    quotes_open = 0  # 1 when the previous chunk ended inside a string
    bs_run = 0  # backslashes ending the previous chunk
    best, best_at, commas, colons = 0, 0, 0, 0
    for start in range(0, a_all.size, _SCAN_CHUNK):
        chunk = a_all[start : start + _SCAN_CHUNK]
        pos = np.flatnonzero(_SCAN_EVENTS[chunk])
        if pos.size == 0:
            bs_run = 0
            continue
        c = chunk[pos]
        e = np.arange(pos.size)
        is_bs = c == 92
        escaped = np.zeros(pos.size, dtype=bool)
        if bs_run or is_bs.any():
            adj = np.empty(pos.size, dtype=bool)
            adj[0] = pos[0] == 0
            adj[1:] = np.diff(pos) == 1
            prev_bs = np.empty(pos.size, dtype=bool)
            prev_bs[0] = bs_run > 0
            prev_bs[1:] = is_bs[:-1]
            cont = is_bs & prev_bs & adj
            run_start = np.maximum.accumulate(np.where(is_bs & ~cont, e, -1))
            run = np.where(is_bs, np.where(run_start >= 0, e - run_start + 1, e + 1 + bs_run), 0)
            prev_run = np.empty(pos.size, dtype=np.int64)
            prev_run[0] = bs_run
            prev_run[1:] = run[:-1]
            escaped = prev_bs & adj & (prev_run % 2 == 1)
            bs_run = int(run[-1]) if is_bs[-1] and pos[-1] == chunk.size - 1 else 0
        else:
            bs_run = 0
        quote = (c == 34) & ~escaped
        line_start = np.maximum.accumulate(np.where((c == 10) | (c == 13), e, -1))
        has_start = line_start >= 0
        ls = np.maximum(line_start, 0)
        qcum = np.cumsum(quote, dtype=np.int64) + quotes_open
        qbase = np.where(has_start, qcum[ls], 0)
        outside = ((qcum - qbase) & 1) == 0
        step = ((c == 91) | (c == 123)).astype(np.int64) - ((c == 93) | (c == 125))
        d = np.cumsum(np.where(outside, step, 0)) + depth
        rel = d - np.where(has_start, d[ls], line_base) if per_line else d
        k = int(np.argmax(rel))
        if int(rel[k]) > best:
            best, best_at = int(rel[k]), start + int(pos[k])
        commas += int(np.count_nonzero((c == 44) & outside))
        colons += int(np.count_nonzero((c == 58) & outside))
        depth = int(d[-1])
        if per_line and has_start[-1]:
            line_base = int(d[ls[-1]])
        quotes_open = int((qcum[-1] - qbase[-1]) & 1)
    return best, best_at, commas, colons


def _check_json_structure(data: bytes, *, per_line: bool, limits: ParseLimits) -> tuple[int, int]:
    """Depth and value count of a JSON body within the limits; returns (keys, max depth)."""
    depth, at, commas, colons = json_scan(data, per_line=per_line)
    if depth > limits.max_json_depth:
        line = data.count(b"\n", 0, at)
        raise LimitExceededError(
            f"JSON nested {depth:,} deep at line {line + 1} (byte {at}) exceeds the limit "
            f"max_json_depth = {limits.max_json_depth} (a sample is one flat object)",
            limit_name="max_json_depth",
            limit=limits.max_json_depth,
        )
    if commas + 1 > limits.max_cells:
        raise _limit("values in the JSON body", commas + 1, "max_cells", limits.max_cells)
    return colons, depth
