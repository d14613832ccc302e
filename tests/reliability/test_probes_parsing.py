"""Black-box probes of the parsers against a real ``orbitcal serve`` (framework: ``probes.py``).

Each probe is one crafted upload with the status, the words of the message and the stored row
count it must produce; after each one the server process must be alive and healthy, and its peak
memory is recorded per class (``docs/reliability.md``). Classes: nesting depth, columns, rows and
cells, text length, decompressed bytes, compressed-stream integrity, repeated names, non-UTF-8
text, booleans where numbers belong, times (sub-microsecond duplicates, leap seconds), CCSDS
packets, all-rows-rejected, and valid bodies whose stored values must equal what was sent. The
storage-sensitive classes run on PostgreSQL too (marked ``services``).
"""

from __future__ import annotations

import gzip
import io
import zlib
from collections.abc import Callable, Iterator

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from probes import Probe, ServeProcess, check_stored_equal, serve_process

from orbitcal import ccsds
from orbitcal.telemetry import DEFAULT_LIMITS as LIM

CSV = {"content-type": "text/csv"}
NDJSON = {"content-type": "application/x-ndjson"}
JSON = {"content-type": "application/json"}
PARQUET = {"content-type": "application/vnd.apache.parquet"}
PACKETS = {"content-type": "application/vnd.ccsds.space-packet"}
GZ = {"content-encoding": "gzip"}
T0 = 1_659_312_000.0  # 2022-08-01T00:00:00Z
#: 2016-12-31T23:59:60 UTC was a leap second; 2017-01-01T00:00:00Z is POSIX 1483228800.
NEW_YEAR_2017 = 1_483_228_800.0


# --- bodies --------------------------------------------------------------------------------------


def _b(n: int, seed: int = 0) -> np.ndarray:
    return np.round(np.random.default_rng(seed).normal(0.0, 2e4, (n, 3)), 3)


def csv_rows(n: int, t0: float = T0, *, seed: int = 0) -> tuple[bytes, np.ndarray, np.ndarray]:
    """A valid CSV of ``n`` rows, its times [µs] and fields [nT]."""
    b = _b(n, seed)
    t = t0 + np.arange(n)
    lines = ["time,b_x,b_y,b_z"] + [
        f"{ti:.6f},{x!r},{y!r},{z!r}" for ti, (x, y, z) in zip(t, b.tolist(), strict=True)
    ]
    return ("\n".join(lines) + "\n").encode(), np.rint(t * 1e6).astype(np.int64), b


def ndjson_rows(n: int, t0: float = T0, **extra: object) -> bytes:
    b = _b(n).tolist()
    return b"\n".join(
        orjson.dumps({"time": t0 + i, "b_x": b[i][0], "b_y": b[i][1], "b_z": b[i][2], **extra})
        for i in range(n)
    )


def parquet_bytes(table: pa.Table, **kwargs: object) -> bytes:
    sink = io.BytesIO()
    pq.write_table(table, sink, **kwargs)  # type: ignore[arg-type]
    return sink.getvalue()


def valid_table(n: int, t0: float = T0) -> pa.Table:
    b = _b(n)
    return pa.table(
        {"time": t0 + np.arange(n, dtype=float), "b_x": b[:, 0], "b_y": b[:, 1], "b_z": b[:, 2]}
    )


def nested(depth: int, inner: bytes = b"1") -> bytes:
    return b"[" * depth + inner + b"]" * depth


def ndjson_with_hk(raw_value: bytes, n_good: int = 3) -> bytes:
    good = ndjson_rows(n_good)
    bad = b'{"time": 1659400000.0, "b_x": 1.0, "b_y": 2.0, "b_z": 3.0, "hk_v": ' + raw_value + b"}"
    return good + b"\n" + bad + b"\n"


def stored_as_sent(body: bytes) -> Callable[[ServeProcess, str, object], None]:
    """Check: the spacecraft holds exactly the CSV rows of ``body`` (every value bit-for-bit)."""
    lines = body.decode().strip().splitlines()[1:]
    t = np.array([round(float(ln.split(",")[0]) * 1e6) for ln in lines], dtype=np.int64)
    b = np.array([[float(v) for v in ln.split(",")[1:4]] for ln in lines])
    return check_stored_equal(t, b)  # type: ignore[return-value]


# --- probe classes -------------------------------------------------------------------------------

PROBES: list[Probe] = []
#: Classes whose outcome depends on the database too (run on PostgreSQL as well).
STORAGE_CLASSES = {"gzip-integrity", "booleans", "times", "all-rejected", "stored-equal", "ccsds"}


def add(*probes: Probe) -> None:
    PROBES.extend(probes)


# 1. Nesting depth, checked on the raw bytes before orjson (the 100,000-deep body killed serve).
for depth in (9, 20, 100, 1_000, 10_000, 100_000, 1_000_000):
    add(
        Probe(
            f"ndjson-hk-nested-{depth}",
            "nesting",
            ndjson_with_hk(nested(depth)),
            NDJSON,
            413,
            ("max_json_depth", "line 4"),
        ),
        Probe(
            f"json-array-nested-{depth}",
            "nesting",
            b'[{"time": 1659312000, "b_x": 1, "b_y": 2, "b_z": 3, "hk_v": ' + nested(depth) + b"}]",
            JSON,
            413,
            ("max_json_depth",),
        ),
    )
add(
    Probe("ndjson-bare-nesting-200k", "nesting", nested(200_000), NDJSON, 413, ("max_json_depth",)),
    Probe(
        "json-objects-nested-50k",
        "nesting",
        b'{"a":' * 50_000 + b"1" + b"}" * 50_000,
        JSON,
        413,
        ("max_json_depth",),
    ),
    Probe("ndjson-unclosed-nesting", "nesting", b"[" * 100_000, NDJSON, 413, ("max_json_depth",)),
    # brackets inside a string are text, not nesting: a flat object within the limits is stored
    Probe(
        "ndjson-brackets-in-string",
        "nesting",
        ndjson_with_hk(b'"' + b"[" * 1000 + b'"'),
        NDJSON,
        200,
        stored=4,
    ),
    # an escaped quote does not end the string: the brackets after it are still text
    Probe(
        "ndjson-escaped-quote-brackets",
        "nesting",
        ndjson_with_hk(b'"\\"' + b"[" * 500 + b'"'),
        NDJSON,
        200,
        stored=4,
    ),
    Probe(
        "ndjson-depth-at-limit",
        "nesting",
        ndjson_with_hk(nested(LIM.max_json_depth - 1)),
        NDJSON,
        200,
        says=("hk_v holds a JSON array",),  # within the depth limit, still not one value
        stored=3,
    ),
)

# 2. Columns: counted from the CSV header / Parquet metadata / JSON keys before the table is built.
wide_header = ",".join(["time", "b_x", "b_y", "b_z"] + [f"hk_{i}" for i in range(99_996)])
add(
    Probe(
        "csv-100k-columns-200kB",
        "columns",
        (wide_header + "\n").encode() + b"1,2,3,4\n",
        CSV,
        413,
        ("max_columns",),
    ),
    Probe(
        "csv-100k-empty-columns",
        "columns",
        b"time,b_x,b_y,b_z" + b"," * 100_000 + b"\n",
        CSV,
        413,
        ("max_columns",),
    ),
    Probe(
        "csv-257-columns",
        "columns",
        (
            ",".join(["time", "b_x", "b_y", "b_z"] + [f"hk_{i}" for i in range(253)])
            + "\n"
            + "1659312000,"
            + ",".join(["1"] * 256)
            + "\n"
        ).encode(),
        CSV,
        413,
        ("max_columns",),
    ),
    Probe(
        "csv-256-columns-ok",
        "columns",
        (
            ",".join(["time", "b_x", "b_y", "b_z"] + [f"hk_{i}" for i in range(252)])
            + "\n"
            + "1659312000,"
            + ",".join(["1"] * 255)
            + "\n"
        ).encode(),
        CSV,
        200,
        stored=1,
    ),
    Probe(
        "csv-long-column-name",
        "columns",
        b"time,b_x,b_y,b_z,hk_" + b"x" * 500 + b"\n1,2,3,4,5\n",
        CSV,
        413,
        ("max_name_chars",),
    ),
    Probe(
        "csv-1MB-column-name",
        "columns",
        b"time,b_x,b_y,b_z,hk_" + b"x" * 2**20 + b"\n",
        CSV,
        413,
        ("max_name_chars",),
    ),
    Probe(
        "ndjson-300-keys-across-lines",
        "columns",
        b"\n".join(
            orjson.dumps({"time": T0 + i, "b_x": 1, "b_y": 2, "b_z": 3, f"hk_{i}": 1})
            for i in range(300)
        ),
        NDJSON,
        413,
        ("max_columns",),
    ),
    Probe(
        "json-300-keys-one-object",
        "columns",
        orjson.dumps(
            [{"time": T0, "b_x": 1, "b_y": 2, "b_z": 3, **{f"hk_{i}": i for i in range(300)}}]
        ),
        JSON,
        413,
        ("max_columns",),
    ),
    Probe(
        "json-columns-300",
        "columns",
        orjson.dumps(
            {
                "time": [T0],
                "b_x": [1],
                "b_y": [2],
                "b_z": [3],
                **{f"hk_{i}": [i] for i in range(300)},
            }
        ),
        JSON,
        413,
        ("max_columns",),
    ),
    Probe(
        "parquet-300-columns",
        "columns",
        lambda: parquet_bytes(
            pa.table(
                {
                    "time": [T0],
                    "b_x": [1.0],
                    "b_y": [2.0],
                    "b_z": [3.0],
                    **{f"hk_{i}": [1.0] for i in range(300)},
                }
            )
        ),
        PARQUET,
        413,
        ("max_columns",),
    ),
)


# 3. Rows and cells: from line counts, Parquet metadata and the JSON value count, before parsing.
def _parquet_2m_rows() -> bytes:
    n = 2_000_000
    table = pa.table(
        {
            "time": pa.array(np.full(n, T0)),
            "b_x": pa.array(np.zeros(n)),
            "b_y": pa.array(np.zeros(n)),
            "b_z": pa.array(np.zeros(n)),
        }
    )
    return parquet_bytes(table, compression="zstd")


def _parquet_many_row_groups() -> bytes:
    return parquet_bytes(valid_table(20_000), row_group_size=1)


add(
    Probe("parquet-2M-rows-small-file", "rows", _parquet_2m_rows, PARQUET, 413, ("max_rows",)),
    Probe(
        "parquet-20k-row-groups-ok", "rows", _parquet_many_row_groups, PARQUET, 200, stored=20_000
    ),
    Probe(
        "csv-1M+1-rows",
        "rows",
        lambda: b"time,b_x,b_y,b_z\n" + b"1,2,3,4\n" * (LIM.max_rows + 1),
        CSV,
        413,
        ("max_rows",),
    ),
    Probe(
        "ndjson-1M+1-rows", "rows", lambda: b"{}\n" * (LIM.max_rows + 1), NDJSON, 413, ("max_rows",)
    ),
    Probe(
        "json-1M+1-objects",
        "rows",
        lambda: b"[" + b",".join([b"{}"] * (LIM.max_rows + 1)) + b"]",
        JSON,
        413,
        ("max_rows",),
    ),
    Probe(
        "json-16M-values",
        "rows",
        lambda: b"[" + b"0," * LIM.max_cells + b"0]",
        JSON,
        413,
        ("max_cells",),
    ),
    Probe(
        "csv-cells-over-limit",
        "rows",
        lambda: (
            (
                ",".join(["time", "b_x", "b_y", "b_z"] + [f"hk_{i}" for i in range(96)]) + "\n"
            ).encode()
            + b"\n" * 200_000
        ),
        CSV,
        413,
        ("max_cells",),
    ),
    Probe("csv-200k-rows-ok", "rows", lambda: csv_rows(200_000)[0], CSV, 200, stored=200_000),
)

# Line ends other than LF count too (pyarrow and pandas split on a lone CR).
add(
    Probe(
        "csv-cr-only-1M+1-rows",
        "rows",
        lambda: b"time,b_x,b_y,b_z\r" + b"1,2,3,4\r" * (LIM.max_rows + 1),
        CSV,
        413,
        ("max_rows",),
    ),
    Probe(
        "csv-cr-only-ok",
        "rows",
        b"time,b_x,b_y,b_z\r1659312000,1,2,3\r1659312001,4,5,6\r",
        CSV,
        200,
        stored=2,
    ),
    Probe(
        "ndjson-cr-quote-then-deep",
        "nesting",
        ndjson_rows(2) + b'\r"\r' + nested(5000) + b"\r",
        NDJSON,
        413,
        ("max_json_depth",),
    ),
)

# 4. Text length.
add(
    Probe(
        "ndjson-hk-text-5000",
        "strings",
        ndjson_with_hk(b'"' + b"x" * 5000 + b'"'),
        NDJSON,
        413,
        ("max_string_chars", "hk_v"),
    ),
    Probe(
        "csv-time-1MB",
        "strings",
        b"time,b_x,b_y,b_z\n" + b"9" * 2**20 + b",1,2,3\n",
        CSV,
        413,
        ("max_string_chars",),
    ),
    Probe(
        "csv-hk-text-60kB",
        "strings",
        b"time,b_x,b_y,b_z,hk_s\n1659312000,1,2,3," + b"a" * 60_000 + b"\n",
        CSV,
        413,
        ("max_string_chars", "hk_s"),
    ),
    Probe(
        "parquet-text-10kB",
        "strings",
        lambda: parquet_bytes(
            pa.table(
                {"time": [T0], "b_x": [1.0], "b_y": [2.0], "b_z": [3.0], "hk_s": ["y" * 10_000]}
            )
        ),
        PARQUET,
        413,
        ("max_string_chars",),
    ),
    Probe(
        "csv-hk-text-4096-ok",
        "strings",
        b"time,b_x,b_y,b_z,hk_s\n1659312000,1,2,3," + b"a" * 4096 + b"\n",
        CSV,
        200,
        stored=1,
    ),
)

# 5. Decompressed bytes (the body limit applies after decompression).
add(
    Probe(
        "gzip-bomb-1GiB",
        "decompressed",
        lambda: gzip.compress(b"0" * 2**30, 9),
        {**CSV, **GZ},
        413,
        ("exceeds",),
    ),
    Probe(
        "deflate-bomb-512MiB",
        "decompressed",
        lambda: zlib.compress(b"1" * 2**29, 9),
        {**CSV, "content-encoding": "deflate"},
        413,
        ("exceeds",),
    ),
    Probe(
        "gzip-members-sum-over-limit",
        "decompressed",
        lambda: gzip.compress(b"0" * 40 * 2**20) * 2,
        {**CSV, **GZ},
        413,
        ("exceeds",),
    ),
)

# 6. Compressed streams: whole, or refused with nothing stored.
_body, _, _ = csv_rows(50, T0 + 10_000)
_gz = gzip.compress(_body)
for cut in (1, 10, 18, len(_gz) // 3, len(_gz) // 2, len(_gz) - 8, len(_gz) - 4, len(_gz) - 1):
    add(
        Probe(
            f"gzip-truncated-at-{cut}", "gzip-integrity", _gz[:cut], {**CSV, **GZ}, 400, ("gzip",)
        )
    )
_z = zlib.compress(_body)
for cut in (2, len(_z) // 2, len(_z) - 4, len(_z) - 1):
    add(
        Probe(
            f"deflate-truncated-at-{cut}",
            "gzip-integrity",
            _z[:cut],
            {**CSV, "content-encoding": "deflate"},
            400,
            ("deflate",),
        )
    )
_flip = bytearray(_gz)
_flip[-6] ^= 0xFF  # CRC-32 in the trailer
_isize = bytearray(_gz)
_isize[-1] ^= 0x01  # ISIZE in the trailer
_half = _body[: len(_body) // 2]
_rest = _body[len(_body) // 2 :]
add(
    Probe(
        "gzip-trailing-garbage",
        "gzip-integrity",
        _gz + b"garbage",
        {**CSV, **GZ},
        400,
        ("follow the end",),
    ),
    Probe(
        "gzip-trailing-zeros",
        "gzip-integrity",
        _gz + bytes(16),
        {**CSV, **GZ},
        400,
        ("follow the end",),
    ),
    Probe(
        "gzip-member-then-garbage",
        "gzip-integrity",
        _gz + _gz + b"\x00junk",
        {**CSV, **GZ},
        400,
        ("follow the end",),
    ),
    Probe(
        "gzip-second-member-truncated",
        "gzip-integrity",
        gzip.compress(_half) + gzip.compress(_rest)[:-5],
        {**CSV, **GZ},
        400,
        ("truncated",),
    ),
    Probe("gzip-bad-crc", "gzip-integrity", bytes(_flip), {**CSV, **GZ}, 400, ("gzip",)),
    Probe("gzip-bad-isize", "gzip-integrity", bytes(_isize), {**CSV, **GZ}, 400, ("gzip",)),
    Probe(
        "deflate-trailing-garbage",
        "gzip-integrity",
        _z + b"xx",
        {**CSV, "content-encoding": "deflate"},
        400,
        ("follow the end",),
    ),
    Probe(
        "deflate-raw-no-header",
        "gzip-integrity",
        zlib.compress(_body)[2:-4],
        {**CSV, "content-encoding": "deflate"},
        400,
        ("deflate",),
    ),
    Probe("gzip-declared-plain-body", "gzip-integrity", _body, {**CSV, **GZ}, 400, ("gzip",)),
    Probe("gzip-empty-body", "gzip-integrity", b"", {**CSV, **GZ}, 400, ("empty",)),
    Probe(
        "gzip-twice-declared",
        "gzip-integrity",
        gzip.compress(_gz),
        {**CSV, "content-encoding": "gzip, gzip"},
        400,
        ("one coding",),
    ),
    Probe(
        "brotli-declared",
        "gzip-integrity",
        _body,
        {**CSV, "content-encoding": "br"},
        400,
        ("not supported",),
    ),
    Probe(
        "gzip-two-members-whole",
        "gzip-integrity",
        gzip.compress(_half) + gzip.compress(_rest),
        {**CSV, **GZ},
        200,
        stored=50,
        check=stored_as_sent(_body),
    ),
    Probe(
        "gzip-ok", "gzip-integrity", _gz, {**CSV, **GZ}, 200, stored=50, check=stored_as_sent(_body)
    ),
    Probe(
        "x-gzip-ok",
        "gzip-integrity",
        _gz,
        {**CSV, "content-encoding": "x-gzip"},
        200,
        stored=50,
        check=stored_as_sent(_body),
    ),
    Probe(
        "deflate-ok",
        "gzip-integrity",
        _z,
        {**CSV, "content-encoding": "deflate"},
        200,
        stored=50,
        check=stored_as_sent(_body),
    ),
    Probe(
        "identity-ok",
        "gzip-integrity",
        _body,
        {**CSV, "content-encoding": "identity"},
        200,
        stored=50,
    ),
    Probe(
        "gzip-parquet-ok",
        "gzip-integrity",
        lambda: gzip.compress(parquet_bytes(valid_table(30))),
        {**PARQUET, **GZ},
        200,
        stored=30,
    ),
)

# 7. Repeated names and non-UTF-8 text: 400 naming the column / row.
add(
    Probe(
        "csv-repeated-b_x",
        "names",
        b"time,b_x,b_x,b_z\n1659312000,1,2,3\n",
        CSV,
        400,
        ("repeated column name", "b_x"),
    ),
    Probe(
        "csv-repeated-time",
        "names",
        b"time,b_x,b_y,b_z,time\n1659312000,1,2,3,1\n",
        CSV,
        400,
        ("repeated column name", "time"),
    ),
    Probe(
        "csv-repeated-after-trim",
        "names",
        b"time,b_x, b_x ,b_y,b_z\n1659312000,1,2,2,3\n",
        CSV,
        400,
        ("repeated column name", "b_x"),
    ),
    Probe(
        "csv-repeated-hk",
        "names",
        b"time,b_x,b_y,b_z,hk_a,hk_a\n1659312000,1,2,3,4,5\n",
        CSV,
        400,
        ("repeated column name", "hk_a"),
    ),
    Probe(
        "parquet-repeated-column",
        "names",
        lambda: parquet_bytes(
            pa.Table.from_arrays(
                [
                    pa.array([T0]),
                    pa.array([1.0]),
                    pa.array([2.0]),
                    pa.array([3.0]),
                    pa.array([4.0]),
                ],
                names=["time", "b_x", "b_y", "b_z", "b_x"],
            )
        ),
        PARQUET,
        400,
        ("repeated column name", "b_x"),
    ),
    Probe(
        "json-columns-repeated-key",
        "names",
        b'{"time": [1659312000], "b_x": [1], "b_y": [2], "b_z": [3], "b_x": [9]}',
        JSON,
        400,
        ("repeated key",),
    ),
    Probe(
        "ndjson-repeated-key-row",
        "names",
        ndjson_rows(3) + b'\n{"time": 1659400000, "b_x": 1, "b_x": 5, "b_y": 2, "b_z": 3}\n',
        NDJSON,
        200,
        ("repeated key 'b_x'",),
        stored=3,
    ),
    Probe(
        "json-repeated-key-row",
        "names",
        b'[{"time": 1659312000, "b_x": 1, "b_y": 2, "b_z": 3},'
        b' {"time": 1659312001, "b_y": 2, "b_y": 7, "b_x": 1, "b_z": 3}]',
        JSON,
        200,
        ('"row":1', "repeated key 'b_y'"),
        stored=1,
    ),
    Probe(
        "csv-latin1-row",
        "utf8",
        b"time,b_x,b_y,b_z,hk_s\n1659312000,1,2,3,ok\n1659312001,1,2,3,caf\xe9\n",
        CSV,
        400,
        ("row 1", "UTF-8"),
    ),
    Probe(
        "csv-latin1-header",
        "utf8",
        b"time,b_x,b_y,b_z,hk_\xe9\n1659312000,1,2,3,4\n",
        CSV,
        400,
        ("header", "UTF-8"),
    ),
    Probe(
        "csv-lone-surrogate",
        "utf8",
        b"time,b_x,b_y,b_z,hk_s\n1659312000,1,2,3,\xed\xa0\x80\n",
        CSV,
        400,
        ("row 0", "UTF-8"),
    ),
    Probe(
        "csv-utf16-body",
        "utf8",
        "time,b_x,b_y,b_z\n1659312000,1,2,3\n".encode("utf-16"),
        CSV,
        400,
        ("UTF-8",),
    ),
    Probe(
        "ndjson-latin1-value",
        "utf8",
        ndjson_rows(2) + b'\n{"time": 1659400000, "b_x": 1, "b_y": 2, "b_z": 3, "hk_s": "\xe9"}',
        NDJSON,
        200,
        ("row", "JSON"),
        stored=2,
    ),
    Probe(
        "parquet-string-not-utf8",
        "utf8",
        lambda: parquet_bytes(
            pa.table(
                {
                    "time": pa.array([T0, T0 + 1]),
                    "b_x": [1.0, 1.0],
                    "b_y": [2.0, 2.0],
                    "b_z": [3.0, 3.0],
                    "hk_s": pa.Array.from_buffers(
                        pa.string(),
                        2,
                        [
                            None,
                            pa.py_buffer(np.array([0, 2, 4], dtype=np.int32).tobytes()),
                            pa.py_buffer(b"ok\xff\xfe"),
                        ],
                    ),
                }
            )
        ),
        PARQUET,
        400,
        ("hk_s", "UTF-8"),
    ),
    Probe(
        "parquet-time-not-utf8",
        "utf8",
        lambda: parquet_bytes(
            pa.table(
                {
                    "time": pa.Array.from_buffers(
                        pa.string(),
                        1,
                        [
                            None,
                            pa.py_buffer(np.array([0, 3], dtype=np.int32).tobytes()),
                            pa.py_buffer(b"\xc3\x28\xa0"),
                        ],
                    ),
                    "b_x": [1.0],
                    "b_y": [2.0],
                    "b_z": [3.0],
                }
            )
        ),
        PARQUET,
        400,
        ("time", "UTF-8"),
    ),
    Probe(
        "parquet-nested-column",
        "names",
        lambda: parquet_bytes(
            pa.table({"time": [T0], "b_x": [[1.0, 2.0]], "b_y": [2.0], "b_z": [3.0]})
        ),
        PARQUET,
        400,
        ("b_x", "flat"),
    ),
    Probe(
        "parquet-binary-column",
        "names",
        lambda: parquet_bytes(
            pa.table(
                {
                    "time": [T0],
                    "b_x": [1.0],
                    "b_y": [2.0],
                    "b_z": [3.0],
                    "hk_raw": pa.array([b"\x00\x01"], pa.binary()),
                }
            )
        ),
        PARQUET,
        400,
        ("hk_raw",),
    ),
)

# 8. Booleans where numbers belong: rejected rows (never stored as 1 or 0).
add(
    Probe(
        "json-b_x-true-only-row",
        "booleans",
        b'[{"time": 1659312000, "b_x": true, "b_y": 2, "b_z": 3}]',
        JSON,
        422,
        ("b_x is a boolean",),
        stored=0,
    ),
    Probe(
        "json-b_x-true-beside-good",
        "booleans",
        b'[{"time": 1659312000, "b_x": 1.5, "b_y": 2, "b_z": 3},'
        b' {"time": 1659312001, "b_x": true, "b_y": 2, "b_z": 3}]',
        JSON,
        200,
        ("b_x is a boolean",),
        stored=1,
    ),
    Probe(
        "ndjson-b_z-false",
        "booleans",
        ndjson_rows(2) + b'\n{"time": 1659400000, "b_x": 1, "b_y": 2, "b_z": false}',
        NDJSON,
        200,
        ("b_z is a boolean",),
        stored=2,
    ),
    Probe(
        "csv-b_y-true-column",
        "booleans",
        b"time,b_x,b_y,b_z\n1659312000,1,true,3\n1659312001,1,false,3\n",
        CSV,
        422,
        ("b_y is a boolean",),
        stored=0,
    ),
    Probe(
        "csv-quaternion-true",
        "booleans",
        b"time,b_x,b_y,b_z,q_w,q_x,q_y,q_z\n1659312000,1,2,3,true,false,false,false\n",
        CSV,
        422,
        ("q_w is a boolean",),
    ),
    Probe(
        "parquet-bool-column",
        "booleans",
        lambda: parquet_bytes(pa.table({"time": [T0], "b_x": [True], "b_y": [2.0], "b_z": [3.0]})),
        PARQUET,
        422,
        ("b_x is a boolean",),
    ),
    Probe(
        "json-columns-bool",
        "booleans",
        b'{"time": [1659312000, 1659312001], "b_x": [1, true], "b_y": [2, 2], "b_z": [3, 3]}',
        JSON,
        200,
        ("b_x is a boolean",),
        stored=1,
    ),
    Probe(
        "json-time-true",
        "booleans",
        b'[{"time": true, "b_x": 1, "b_y": 2, "b_z": 3}]',
        JSON,
        422,
        ("boolean",),
    ),
    Probe(
        "json-string-true",
        "booleans",
        b'[{"time": 1659312000, "b_x": "true", "b_y": 2, "b_z": 3}]',
        JSON,
        422,
        ("b_x is not a number",),
    ),
    Probe(
        "json-hk-flag-ok",
        "booleans",
        b'[{"time": 1659312000, "b_x": 1, "b_y": 2, "b_z": 3, "hk_flag": true}]',
        JSON,
        200,
        stored=1,
    ),
)

# 9. Times: sub-microsecond duplicates and leap seconds are named, never merged silently.
add(
    Probe(
        "csv-sub-us-duplicate",
        "times",
        b"time,b_x,b_y,b_z\n1659312000.0000001,1,2,3\n1659312000.0000003,4,5,6\n",
        CSV,
        200,
        ("duplicate time", "microsecond", "row 0 kept"),
        stored=1,
    ),
    Probe(
        "csv-iso-sub-us-duplicate",
        "times",
        b"time,b_x,b_y,b_z\n2022-08-01T00:00:00.0000001Z,1,2,3\n"
        b"2022-08-01T00:00:00.0000004Z,4,5,6\n2022-08-01T00:00:01Z,7,8,9\n",
        CSV,
        200,
        ("microsecond",),
        stored=2,
    ),
    Probe(
        "csv-leap-second",
        "times",
        b"time,b_x,b_y,b_z\n2016-12-31T23:59:59Z,1,2,3\n2016-12-31T23:59:60Z,4,5,6\n"
        b"2017-01-01T00:00:00Z,7,8,9\n",
        CSV,
        200,
        ("leap second", "23:59:60", 'row":1'),
        stored=2,
        check=check_stored_equal(
            np.array([NEW_YEAR_2017 - 1, NEW_YEAR_2017]) * 1e6, np.array([[1, 2, 3], [7, 8, 9.0]])
        ),
    ),
    Probe(
        "csv-leap-second-fraction",
        "times",
        b"time,b_x,b_y,b_z\n2016-12-31T23:59:60.5Z,4,5,6\n2017-01-01T00:00:00.5Z,7,8,9\n",
        CSV,
        200,
        ("leap second",),
        stored=1,
    ),
    Probe(
        "ndjson-leap-second-offset",
        "times",
        b'{"time": "2016-12-31T23:59:60+00:00", "b_x": 1, "b_y": 2, "b_z": 3}\n'
        b'{"time": "2017-01-01T00:00:00Z", "b_x": 1, "b_y": 2, "b_z": 3}\n',
        NDJSON,
        200,
        ("leap second",),
        stored=1,
    ),
    Probe(
        "json-leap-second-only",
        "times",
        b'[{"time": "2016-12-31T23:59:60Z", "b_x": 1, "b_y": 2, "b_z": 3}]',
        JSON,
        422,
        ("leap second",),
    ),
    Probe(
        "csv-tai-inside-leap-second",
        "times",
        # 2017-01-01T00:00:36 TAI is 2016-12-31T23:59:60 UTC; 00:00:37 TAI is 00:00:00 UTC
        b"time,b_x,b_y,b_z\n2017-01-01T00:00:36.5Z,1,2,3\n2017-01-01T00:00:37Z,4,5,6\n",
        CSV,
        200,
        ("leap second",),
        stored=1,
        params={"time_scale": "TAI"},
    ),
    Probe(
        "csv-exact-duplicate",
        "times",
        b"time,b_x,b_y,b_z\n1659312000,1,2,3\n1659312000,4,5,6\n",
        CSV,
        200,
        ("duplicate time", "row 0 kept"),
        stored=1,
    ),
    Probe(
        "csv-year-2201",
        "times",
        b"time,b_x,b_y,b_z\n2201-01-01T00:00:00Z,1,2,3\n",
        CSV,
        422,
        ("2200",),
    ),
)


# 10. CCSDS packets.
def _packets(n: int, t0: float = T0, **kw: object) -> bytes:
    return ccsds.encode_packets(t0 + np.arange(n, dtype=float), _b(n), **kw)  # type: ignore[arg-type]


def _zero_time(data: bytes, k: int) -> bytes:
    out = bytearray(data)
    out[k * 85 + 6 : k * 85 + 13] = bytes(7)
    return bytes(out)


def _tiny_packets(n: int) -> bytes:
    hdr = ((1 << 11) | ccsds.DEFAULT_APID).to_bytes(2, "big") + (0xC000).to_bytes(2, "big")
    return (hdr + (0).to_bytes(2, "big") + b"\x00") * n  # 7-octet packets


add(
    Probe(
        "ccsds-zero-time",
        "ccsds",
        _zero_time(_packets(3), 1),
        PACKETS,
        200,
        ("before 1972",),
        stored=2,
    ),
    Probe("ccsds-all-zero-time", "ccsds", bytes(85 * 4), PACKETS, 422, ("rejected",)),
    Probe(
        "ccsds-leap-second",
        "ccsds",
        ccsds.encode_packets(np.array([NEW_YEAR_2017 - 1.0]), np.ones((1, 3)))[:6]
        # TAI 2017-01-01T00:00:36 (= 23:59:60 UTC): coarse seconds since 1958 TAI
        + int(NEW_YEAR_2017 + 36 + ccsds.TAI_1958_TO_UNIX_S).to_bytes(4, "big")
        + ccsds.encode_packets(np.array([NEW_YEAR_2017 - 1.0]), np.ones((1, 3)))[10:]
        + _packets(1, NEW_YEAR_2017),
        PACKETS,
        200,
        ("leap second",),
        stored=1,
    ),
    Probe(
        "ccsds-9M-tiny-packets",
        "ccsds",
        lambda: _tiny_packets(9_000_000),
        PACKETS,
        413,
        ("max_rows",),
    ),
    Probe("ccsds-ok", "ccsds", _packets(100), PACKETS, 200, stored=100),
    Probe("ccsds-garbage", "ccsds", bytes(range(256)) * 10, PACKETS, (400, 422)),
)

# 11. Every row rejected: 422 with the rejected list, nothing stored.
add(
    Probe(
        "csv-all-nan",
        "all-rejected",
        b"time,b_x,b_y,b_z\n1659312000,nan,1,1\n1659312001,1,inf,1\n",
        CSV,
        422,
        ("every row was rejected", '"rejected":[{"row":0'),
    ),
    Probe("csv-header-only", "all-rejected", b"time,b_x,b_y,b_z\n", CSV, 422, ("no data rows",)),
    Probe("ndjson-all-invalid", "all-rejected", b"nope\n{\n[1]\n", NDJSON, (400, 422)),
    Probe(
        "json-all-absurd",
        "all-rejected",
        b'[{"time": 1659312000, "b_x": 1e12, "b_y": 0, "b_z": 0}]',
        JSON,
        422,
        ("|b| above",),
    ),
    Probe(
        "parquet-all-bad-time",
        "all-rejected",
        lambda: parquet_bytes(
            pa.table({"time": ["yesterday"], "b_x": [1.0], "b_y": [2.0], "b_z": [3.0]})
        ),
        PARQUET,
        422,
        ("time",),
    ),
)

# 12. Valid bodies: stored exactly as sent.
_v1, _t1, _b1 = csv_rows(500, T0 + 50_000, seed=3)
add(
    Probe(
        "csv-500-stored-exactly",
        "stored-equal",
        _v1,
        CSV,
        200,
        stored=500,
        check=check_stored_equal(_t1, _b1),
    ),
    Probe(
        "csv-crlf-bom",
        "stored-equal",
        b"\xef\xbb\xbf" + _v1.replace(b"\n", b"\r\n"),
        CSV,
        200,
        stored=500,
        check=check_stored_equal(_t1, _b1),
    ),
    Probe(
        "ndjson-stored",
        "stored-equal",
        ndjson_rows(200),
        NDJSON,
        200,
        stored=200,
        check=check_stored_equal(np.rint((T0 + np.arange(200)) * 1e6).astype(np.int64), _b(200)),
    ),
    Probe(
        "parquet-stored",
        "stored-equal",
        lambda: parquet_bytes(valid_table(300)),
        PARQUET,
        200,
        stored=300,
        check=check_stored_equal(np.rint((T0 + np.arange(300)) * 1e6).astype(np.int64), _b(300)),
    ),
    Probe(
        "csv-sub-us-times-distinct",
        "stored-equal",
        b"time,b_x,b_y,b_z\n1659312000.000001,1,2,3\n1659312000.000002,4,5,6\n",
        CSV,
        200,
        stored=2,
        check=check_stored_equal(
            np.array([1659312000000001, 1659312000000002]), np.array([[1, 2, 3], [4, 5, 6.0]])
        ),
    ),
)

assert len({p.name for p in PROBES}) == len(PROBES), "probe names must be unique"


# --- running -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServeProcess]:
    with serve_process(tmp_path_factory.mktemp("probes-parsing")) as s:
        yield s


@pytest.fixture(scope="module")
def pg_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServeProcess]:
    with serve_process(tmp_path_factory.mktemp("probes-parsing-pg"), database="postgresql") as s:
        yield s


def test_there_are_at_least_100_probes() -> None:
    assert len(PROBES) >= 100, len(PROBES)


@pytest.mark.timeout(600)
@pytest.mark.parametrize("probe", PROBES, ids=lambda p: p.name)
def test_probe(server: ServeProcess, probe: Probe) -> None:
    server.run(probe)


@pytest.mark.services
@pytest.mark.timeout(600)
@pytest.mark.parametrize(
    "probe", [p for p in PROBES if p.klass in STORAGE_CLASSES], ids=lambda p: p.name
)
def test_probe_postgresql(pg_server: ServeProcess, probe: Probe) -> None:
    pg_server.run(probe)


# 13. The largest valid bodies (the worst memory a well-formed upload can cost), marked slow.
def _ndjson_big(n: int) -> bytes:
    return ndjson_rows(n, T0 + 5e6) + b"\n"


def _json_big(n: int) -> bytes:
    b = _b(n).tolist()
    t = (T0 + 6e6 + np.arange(n)).tolist()
    return orjson.dumps(
        [{"time": t[i], "b_x": b[i][0], "b_y": b[i][1], "b_z": b[i][2]} for i in range(n)]
    )


def _bad_rows(n_bad: int, n_good: int) -> bytes:
    rows = [f"{1659312000 + i},nan,1,1" for i in range(n_bad)]
    rows += [f"{1759312000 + i},1,1,1" for i in range(n_good)]
    return ("time,b_x,b_y,b_z\n" + "\n".join(rows) + "\n").encode()


LARGE = [
    Probe(
        "csv-1M-rows-all-rejected",
        "large-rejected",
        lambda: _bad_rows(LIM.max_rows, 0),
        CSV,
        422,
        ("every row was rejected",),
        stored=0,
    ),
    Probe(
        "csv-1M-rows-one-good",
        "large-rejected",
        lambda: _bad_rows(LIM.max_rows - 1, 1),
        CSV,
        200,
        ('"row":999998',),
        stored=1,
    ),
    Probe(
        "csv-1M-rows-max",
        "large-valid",
        lambda: csv_rows(LIM.max_rows, T0 + 1e7)[0],
        CSV,
        200,
        stored=LIM.max_rows,
    ),
    Probe(
        "ndjson-700k-rows", "large-valid", lambda: _ndjson_big(700_000), NDJSON, 200, stored=700_000
    ),
    Probe("json-700k-rows", "large-valid", lambda: _json_big(700_000), JSON, 200, stored=700_000),
    Probe(
        "parquet-1M-rows-max",
        "large-valid",
        lambda: parquet_bytes(valid_table(LIM.max_rows)),
        PARQUET,
        200,
        stored=LIM.max_rows,
    ),
    Probe(
        "ccsds-780k-packets",
        "large-valid",
        lambda: _packets(780_000, T0 + 3e7),
        PACKETS,
        200,
        stored=780_000,
    ),
]


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("probe", LARGE, ids=lambda p: p.name)
def test_largest_valid_bodies(server: ServeProcess, probe: Probe) -> None:
    result = server.run(probe)
    assert result.peak_rss_mb - result.rss_before_mb < 2048, result
