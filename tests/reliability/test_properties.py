"""Property tests (hypothesis) of the two edge parsers: the telemetry readers
(``orbitcal.telemetry.parse_telemetry``) and the CCSDS decoder (``orbitcal.ccsds``).

Properties: valid tables survive every format exactly; bad cells reject exactly their rows and
nothing else; row order does not matter; any bytes either parse or raise the one documented
error (``TelemetryError`` / ``PacketError``), never anything else; packets decode to what was
encoded (to the 2**-24 s CUC resolution) and damage is confined to the damaged packets.
"""

from __future__ import annotations

import io
import subprocess
import sys
import warnings
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from orbitcal import ccsds
from orbitcal.telemetry import TelemetryError, parse_telemetry

FMTS = ("csv", "ndjson", "json", "parquet")
#: 2000-01-01 .. 2030-01-01 [POSIX s], whole microseconds (the service's time resolution).
T_LO_US, T_HI_US = 946_684_800_000_000, 1_893_456_000_000_000
CUC_RESOLUTION_S = 2.0**-24  # 59.6 ns
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

field_nt = st.floats(-9e5 / np.sqrt(3), 9e5 / np.sqrt(3), allow_nan=False, allow_infinity=False)


@st.composite
def tables(draw: Any, *, min_rows: int = 1, max_rows: int = 40) -> pd.DataFrame:
    """A valid section-1 table: unique times, |b| < 1e6 nT, unit quaternions (or none)."""
    n = draw(st.integers(min_rows, max_rows))
    t_us = draw(st.lists(st.integers(T_LO_US, T_HI_US), min_size=n, max_size=n, unique=True))
    b = np.array(draw(st.lists(st.tuples(field_nt, field_nt, field_nt), min_size=n, max_size=n)))
    df = pd.DataFrame({"time": np.array(t_us) / 1e6})
    for i, c in enumerate(("b_x", "b_y", "b_z")):
        df[c] = b[:, i]
    if draw(st.booleans()):
        raw = np.array(
            draw(
                st.lists(
                    st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4), min_size=n, max_size=n
                )
            )
        )
        norm = np.linalg.norm(raw, axis=1)
        raw[norm < 1e-3] = [1.0, 0.0, 0.0, 0.0]
        q = raw / np.linalg.norm(raw, axis=1, keepdims=True)
        for i, c in enumerate(("q_w", "q_x", "q_y", "q_z")):
            df[c] = q[:, i]
    return df


def encode(df: pd.DataFrame, fmt: str) -> bytes:
    if fmt == "csv":
        return df.to_csv(index=False, float_format="%.17g").encode()
    if fmt == "ndjson":
        return df.to_json(orient="records", lines=True, double_precision=15).encode()
    if fmt == "json":
        return df.to_json(orient="records", double_precision=15).encode()
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return buf.getvalue()


#: Text JSON carries 15 significant digits (pandas' maximum); CSV and Parquet every bit.
RTOL = {"csv": 0.0, "parquet": 0.0, "ndjson": 1e-14, "json": 1e-14}


@FAST
@given(df=tables(), fmt=st.sampled_from(FMTS))
def test_valid_tables_survive_every_format(df: pd.DataFrame, fmt: str) -> None:
    result = parse_telemetry(encode(df, fmt), fmt=fmt)  # type: ignore[arg-type]
    assert result.rejected == []
    order = np.argsort(df["time"].to_numpy(), kind="stable")
    tel = result.telemetry
    np.testing.assert_allclose(tel.t_utc_s, df["time"].to_numpy()[order], rtol=0, atol=1e-6)
    b = df[["b_x", "b_y", "b_z"]].to_numpy()[order]
    np.testing.assert_allclose(tel.b_raw_nt, b, rtol=RTOL[fmt], atol=1e-9)
    if "q_w" in df:
        assert tel.q_wxyz is not None
        q = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy()[order]
        np.testing.assert_allclose(tel.q_wxyz, q, rtol=RTOL[fmt], atol=1e-15)
    else:
        assert tel.q_wxyz is None


BAD_CELLS = {
    "nan": float("nan"),
    "inf": float("inf"),
    "absurd": 1e12,
}


@FAST
@given(
    df=tables(min_rows=2),
    fmt=st.sampled_from(("csv", "parquet")),
    data=st.data(),
)
def test_bad_cells_reject_exactly_their_rows(df: pd.DataFrame, fmt: str, data: Any) -> None:
    n = len(df)
    bad_rows = sorted(data.draw(st.sets(st.integers(0, n - 1), max_size=n), label="bad rows"))
    df = df.copy()
    for row in bad_rows:
        col = data.draw(st.sampled_from(("b_x", "b_y", "b_z")), label="column")
        df.loc[row, col] = BAD_CELLS[data.draw(st.sampled_from(sorted(BAD_CELLS)), label="cell")]
    result = parse_telemetry(encode(df, fmt), fmt=fmt)  # type: ignore[arg-type]
    assert [e.row for e in result.rejected] == bad_rows
    assert all(("finite" in e.reason) or ("above" in e.reason) for e in result.rejected)
    good = df.drop(index=bad_rows)
    assert len(result.telemetry) == len(good) == n - len(bad_rows)
    np.testing.assert_array_equal(np.sort(result.telemetry.t_utc_s), np.sort(good["time"]))


@FAST
@given(df=tables(min_rows=2), seed=st.integers(0, 2**32 - 1))
def test_row_order_does_not_matter(df: pd.DataFrame, seed: int) -> None:
    shuffled = df.sample(frac=1.0, random_state=np.random.RandomState(seed))
    a = parse_telemetry(encode(df, "parquet"), fmt="parquet").telemetry
    b = parse_telemetry(encode(shuffled, "parquet"), fmt="parquet").telemetry
    np.testing.assert_array_equal(a.t_utc_s, b.t_utc_s)
    np.testing.assert_array_equal(a.b_raw_nt, b.b_raw_nt)


@pytest.mark.parametrize("body", [b"null", b"\xef\xbb\xbfnull\n", b" \r\nnull\n{}"])
def test_ndjson_starting_with_null_does_not_crash_the_process(body: bytes) -> None:
    """pyarrow 26.0.1's ``pyarrow.json.read_json`` segfaults when the first value is ``null``;
    this test found it (one such upload killed the API). Run in a child process: a regression
    must fail this test, not kill the test run."""
    code = (
        "import sys; from orbitcal.telemetry import parse_telemetry, TelemetryError\n"
        "try: parse_telemetry(sys.stdin.buffer.read(), fmt='ndjson')\n"
        "except TelemetryError: pass\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], input=body, capture_output=True, timeout=120
    )
    assert proc.returncode == 0, f"exit {proc.returncode} (-11 = segmentation fault)"


@settings(max_examples=150, deadline=None)
@given(data=st.binary(max_size=600), fmt=st.sampled_from(FMTS))
def test_any_bytes_parse_or_raise_the_documented_error(data: bytes, fmt: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unknown columns warn; that is allowed
        try:
            result = parse_telemetry(data, fmt=fmt)  # type: ignore[arg-type]
        except TelemetryError as exc:
            assert str(exc)  # a reason the caller can act on
            return
    n_kept = len(result.telemetry)
    assert np.all(np.isfinite(result.telemetry.t_utc_s)) and np.all(
        np.isfinite(result.telemetry.b_raw_nt)
    )
    assert n_kept == 0 or np.all(np.diff(result.telemetry.t_utc_s) > 0)  # sorted, unique
    assert all(e.reason for e in result.rejected)


@settings(max_examples=150, deadline=None)
@given(
    lines=st.lists(
        st.one_of(
            st.text(max_size=40),
            st.sampled_from(
                ['{"time": 1e9, "b_x": 1, "b_y": 2, "b_z": 3}', "{}", "[]", "null", '{"time": "x"}']
            ),
        ),
        max_size=8,
    )
)
# Found on a fresh clone: the old fast path joined all lines into one JSON array, so the lines
# '"' and '"' became the one string "," — a row lost and every later row number shifted.
@example(lines=['"', '"'])
@example(lines=['"', '"', '{"time": 1e9, "b_x": 1, "b_y": 2, "b_z": 3}'])
@example(lines=["[1", "2]"])
def test_ndjson_lines_of_any_text_never_crash(lines: list[str]) -> None:
    body = "\n".join(lines).encode("utf-8", "surrogatepass")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            result = parse_telemetry(body, fmt="ndjson")
        except TelemetryError:
            return
    # every non-blank line is one row: kept or rejected with a reason, never both, never lost
    kept = [ln for ln in body.splitlines() if ln.strip()]
    assert len(result.telemetry) + len(result.rejected) == len(kept)
    assert len({e.row for e in result.rejected}) == len(result.rejected)


# --- CCSDS ------------------------------------------------------------------------------------


@st.composite
def packet_data(draw: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 30))
    t_us = draw(st.lists(st.integers(T_LO_US, T_HI_US), min_size=n, max_size=n))
    b = np.array(draw(st.lists(st.tuples(field_nt, field_nt, field_nt), min_size=n, max_size=n)))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return np.array(t_us) / 1e6, b, q


@FAST
@given(d=packet_data(), apid=st.integers(0, 2047))
def test_packets_decode_to_what_was_encoded(
    d: tuple[np.ndarray, np.ndarray, np.ndarray], apid: int
) -> None:
    t, b, q = d
    decoded = ccsds.decode_packets(ccsds.encode_packets(t, b, q_wxyz=q, apid=apid), apid=apid)
    assert decoded.rejected == []
    np.testing.assert_array_equal(decoded.index, np.arange(len(t)))
    np.testing.assert_array_equal(decoded.b_raw_nt, b)  # binary64 on the wire: exact
    np.testing.assert_array_equal(decoded.q_wxyz, q)
    # half the CUC fine-time step, plus the float64 spacing of POSIX seconds (~0.1-0.2 µs here)
    tolerance_s = CUC_RESOLUTION_S / 2 + 2 * np.spacing(np.abs(t))
    assert np.all(np.abs(decoded.t_utc_s - t) <= tolerance_s)


@FAST
@given(d=packet_data(), data=st.data())
def test_damage_is_confined_to_the_damaged_packets(
    d: tuple[np.ndarray, np.ndarray, np.ndarray], data: Any
) -> None:
    t, b, q = d
    n = len(t)
    stream = bytearray(ccsds.encode_packets(t, b, q_wxyz=q))
    # Cut the stream inside packet k (it and everything after is lost, the rest intact) ...
    k = data.draw(st.integers(0, n - 1), label="cut packet")
    cut = data.draw(st.integers(1, ccsds.PACKET_LENGTH - 1), label="octets kept of it")
    truncated = bytes(stream[: k * ccsds.PACKET_LENGTH + cut])
    dec = ccsds.decode_packets(truncated)
    np.testing.assert_array_equal(dec.index, np.arange(k))
    np.testing.assert_array_equal(dec.b_raw_nt, b[:k])
    assert [i for i, _ in dec.rejected] == [k]
    assert "truncated" in dec.rejected[0][1]
    # ... or give packet j another APID: only packet j is rejected.
    j = data.draw(st.integers(0, n - 1), label="foreign packet")
    assume(ccsds.DEFAULT_APID != 5)
    hdr0 = (1 << 11) | 5
    stream[j * ccsds.PACKET_LENGTH : j * ccsds.PACKET_LENGTH + 2] = hdr0.to_bytes(2, "big")
    dec = ccsds.decode_packets(bytes(stream), apid=ccsds.DEFAULT_APID)
    assert [i for i, _ in dec.rejected] == [j]
    np.testing.assert_array_equal(dec.index, [i for i in range(n) if i != j])
    np.testing.assert_array_equal(dec.b_raw_nt, np.delete(b, j, axis=0))


@settings(max_examples=200, deadline=None)
@given(
    prefix=st.binary(max_size=200),
    lengths=st.lists(st.integers(0, 300), max_size=5),
)
# Found on a fresh clone: a packet whose time field is zero (1958-01-01 TAI, before UTC has
# leap seconds) decoded to a NaN time; it is now rejected with the reason.
@example(prefix=b"", lengths=[78])
@example(prefix=b"", lengths=[78, 78])
def test_decoder_never_crashes_on_headers_with_any_length(
    prefix: bytes, lengths: list[int]
) -> None:
    """Structured garbage: plausible primary headers announcing arbitrary packet lengths."""
    body = bytearray(prefix)
    for i, ln in enumerate(lengths):
        body += ((1 << 11) | ccsds.DEFAULT_APID).to_bytes(2, "big")
        body += ((0b11 << 14) | i).to_bytes(2, "big") + ln.to_bytes(2, "big")
        body += bytes(min(ln + 1, 120))
    if not body:
        return
    dec = ccsds.decode_packets(bytes(body))
    assert len(dec) + len(dec.rejected) >= 1
    assert np.all(np.isfinite(dec.t_utc_s))
    numbers = sorted([*dec.index.tolist(), *(i for i, _ in dec.rejected)])
    assert numbers == sorted(set(numbers))  # each packet number decoded or rejected, once


def test_ndjson_quote_lines_are_two_rows_and_numbering_holds() -> None:
    body = b'"\n"\n{"time": 1e9, "b_x": 1, "b_y": 2, "b_z": 3}\n'
    result = parse_telemetry(body, fmt="ndjson")
    assert [e.row for e in result.rejected] == [0, 1]
    assert all("not valid JSON" in e.reason for e in result.rejected)
    assert len(result.telemetry) == 1


def test_zero_time_packet_is_rejected_with_the_reason() -> None:
    good = ccsds.encode_packets(np.array([T_LO_US / 1e6]), np.ones((1, 3)))
    zero = bytearray(good)
    zero[6:13] = bytes(7)  # CUC coarse and fine time = 0
    dec = ccsds.decode_packets(bytes(zero) + good)
    np.testing.assert_array_equal(dec.index, [1])
    assert [i for i, _ in dec.rejected] == [0]
    assert "before 1972-01-01" in dec.rejected[0][1]


def _scan_reference(data: bytes, per_line: bool) -> tuple[int, int, int]:
    """A byte-by-byte model of ``json_scan``: depth, commas and colons outside strings."""
    depth = best = commas = colons = base = 0
    inside = escaped = False
    for b in data:
        if b in (10, 13):
            inside = escaped = False
            base = depth
            continue
        was_escaped, escaped = escaped, (b == 92 and not escaped)
        if b == 92:
            continue
        if b == 34:
            inside = inside if was_escaped else not inside
            continue
        if inside:
            continue
        depth += (b in (91, 123)) - (b in (93, 125))
        commas += b == 44
        colons += b == 58
        best = max(best, depth - base if per_line else depth)
    return best, commas, colons


@settings(max_examples=300)
@given(data=st.binary(max_size=60).map(lambda b: bytes(b'"\\[]{},:\n\rab'[x % 12] for x in b)))
@example(data=b'["\\"[[[", [[1]]]')
@example(data=b'{"a":"\\\\"}\n[[[[')
def test_json_scan_matches_a_byte_by_byte_model(data: bytes) -> None:
    """The vectorised depth scanner (what guards orjson) against a plain loop, with chunks of a
    few bytes so every carry between chunks (string, backslash run, depth) is exercised."""
    from orbitcal.telemetry import limits as telemetry  # the scanner and its chunk size

    old = telemetry._SCAN_CHUNK
    telemetry._SCAN_CHUNK = 5
    try:
        for per_line in (False, True):
            depth, _, commas, colons = telemetry.json_scan(data, per_line=per_line)
            assert (depth, commas, colons) == _scan_reference(data, per_line)
    finally:
        telemetry._SCAN_CHUNK = old
