"""The magnetometer space-packet layout (orbitcal.ccsds, docs/ccsds.md)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orbitcal import ccsds


def _sample(n: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    t = 1_700_000_000.0 + np.arange(n) * 0.125
    b = rng.normal(0, 3e4, (n, 3))
    q = rng.normal(size=(n, 4))
    return t, b, q / np.linalg.norm(q, axis=1, keepdims=True)


def test_round_trip_is_exact_to_the_cuc_resolution() -> None:
    t, b, q = _sample()
    data = ccsds.encode_packets(t, b, q_wxyz=q, temperature_c=np.full(5, 21.5), apid=0x123)
    assert len(data) == 5 * ccsds.PACKET_LENGTH
    d = ccsds.decode_packets(data)
    assert d.rejected == []
    # 24-bit fine time: 2**-24 s = 60 ns resolution
    np.testing.assert_allclose(d.t_utc_s, t, atol=6e-8, rtol=0)
    np.testing.assert_array_equal(d.b_raw_nt, b)  # binary64: bit-exact
    np.testing.assert_array_equal(d.q_wxyz, q)
    np.testing.assert_array_equal(d.temperature_c, 21.5)
    assert np.isnan(d.mtq_am2).all()  # not given → NaN ("not available")
    assert set(d.apid.tolist()) == {0x123}
    assert d.sequence_count.tolist() == [0, 1, 2, 3, 4]


def test_cuc_time_is_tai_since_1958_with_leap_seconds() -> None:
    # 2017-01-01T00:00:00Z: TAI-UTC = 37 s. TAI seconds since 1958-01-01 = days * 86400 + 37.
    t_utc = np.array([1_483_228_800.0])
    data = ccsds.encode_packets(t_utc, np.zeros((1, 3)))
    coarse = int.from_bytes(data[6:10], "big")
    days_1958_to_2017 = (np.datetime64("2017-01-01") - np.datetime64("1958-01-01")).astype(int)
    assert coarse == days_1958_to_2017 * 86400 + 37
    # one second before the leap second was inserted: TAI-UTC was 36 s
    data = ccsds.encode_packets(t_utc - 1.0, np.zeros((1, 3)))
    assert int.from_bytes(data[6:10], "big") == days_1958_to_2017 * 86400 - 1 + 36
    assert ccsds.decode_packets(data).t_utc_s[0] == t_utc[0] - 1.0


def test_primary_header_matches_spacepackets() -> None:
    from spacepackets.ccsds.spacepacket import PacketType, SpacePacketHeader

    t, b, _ = _sample(2)
    data = ccsds.encode_packets(t, b, apid=0x2B0, first_sequence_count=16383)
    hdr = SpacePacketHeader.unpack(data[: ccsds.PACKET_LENGTH])
    assert hdr.apid == 0x2B0
    assert hdr.packet_type == PacketType.TM
    assert hdr.sec_header_flag
    assert hdr.seq_count == 16383
    assert hdr.data_len == ccsds.PACKET_LENGTH - 7
    assert SpacePacketHeader.unpack(data[ccsds.PACKET_LENGTH :]).seq_count == 0  # wraps at 2**14


def test_truncated_packet_is_rejected_and_the_others_kept() -> None:
    t, b, _ = _sample(3)
    data = ccsds.encode_packets(t, b)
    d = ccsds.decode_packets(data[:-10])
    assert len(d) == 2
    assert d.rejected == [(2, "truncated packet: 75 of 85 octets (stream ends)")]
    d = ccsds.decode_packets(data + b"\x08\xb0")
    assert len(d) == 3 and d.rejected[0][0] == 3 and "header needs 6" in d.rejected[0][1]


def test_other_apid_and_length_are_rejected_by_packet_number() -> None:
    t, b, _ = _sample(3)
    good = ccsds.encode_packets(t, b, apid=7)
    other = ccsds.encode_packets(t[:1] + 10, b[:1], apid=8)
    d = ccsds.decode_packets(good[:85] + other + good[85:], apid=7)
    assert len(d) == 3
    assert d.index.tolist() == [0, 2, 3]
    assert d.rejected == [(1, "APID 8, expected 7")]
    # a packet of another length (data length field 9 → 16 octets) is skipped by its own length
    short = bytes([0x08, 0x07, 0xC0, 0x00, 0x00, 0x09]) + bytes(10)
    d = ccsds.decode_packets(short + good)
    assert len(d) == 3
    assert d.rejected[0] == (0, "packet of 16 octets, the magnetometer layout has 85")


def test_empty_stream_is_an_error() -> None:
    with pytest.raises(ccsds.PacketError):
        ccsds.decode_packets(b"")


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=400))
def test_decoder_never_crashes_on_garbage(data: bytes) -> None:
    if not data:
        return
    d = ccsds.decode_packets(data)
    assert len(d) + len(d.rejected) >= 1
    assert all(isinstance(i, int) and reason for i, reason in d.rejected)
