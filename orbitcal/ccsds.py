"""CCSDS space packets carrying magnetometer samples: the documented layout, decoder and encoder.

One sample per packet, fixed length 85 octets, all fields big-endian (``docs/ccsds.md``):

=======  =====  ==========================================================================
octets   bits   field
=======  =====  ==========================================================================
0–5      48     primary header (CCSDS 133.0-B-2): version 0, type 0 (telemetry), secondary
                header flag 1, APID (11 bits), sequence flags 0b11, sequence count (14 bits),
                packet data length = 78 (octets in the data field minus one)
6–9      32     CUC coarse time: whole TAI seconds since 1958-01-01T00:00:00 TAI
10–12    24     CUC fine time: fraction of a second × 2**24 (resolution 59.6 ns)
13–36    3×64   ``b_x, b_y, b_z`` raw magnetometer output, sensor axes [nT], IEEE-754 binary64
37–68    4×64   ``q_w, q_x, q_y, q_z`` attitude quaternion (CONTRACT section 1 convention), binary64
69–72    32     ``temperature`` sensor temperature [°C], binary32
73–84    3×32   ``mtq_x, mtq_y, mtq_z`` magnetorquer dipole commands [A·m²], binary32
=======  =====  ==========================================================================

The CUC preamble (P-field) is implicit, as CCSDS 301.0-B-4 allows for a mission-fixed code; the
equivalent explicit P-field would be ``0x1F`` (level-1 epoch 1958 TAI, 4 coarse + 3 fine octets).
A NaN in an optional field means "not available". Packets are decoded with ``ccsdspy``; its
datetime converter ignores leap seconds, so the CUC time is converted here: TAI seconds since 1958
→ TAI on the Unix scale → UTC with :mod:`orbitcal.timescales` (leap-second table).
"""

from __future__ import annotations

import io
import logging
from dataclasses import dataclass, field

import numpy as np

from orbitcal.errors import (
    BadInputError,
    LimitExceededError,
    UnreadableInputError,
    reading_untrusted_input,
)

__all__ = [
    "DEFAULT_APID",
    "PACKET_LENGTH",
    "TAI_1958_TO_UNIX_S",
    "DecodedPackets",
    "PacketError",
    "decode_packets",
    "encode_packets",
]

#: Packet length in octets (primary header 6 + secondary header 7 + user data 72).
PACKET_LENGTH = 85
#: The APID orbitcal uses when none is given (any 11-bit value may be configured).
DEFAULT_APID = 0x2B0
#: Seconds from 1958-01-01T00:00:00 to 1970-01-01T00:00:00 on a uniform (TAI) scale.
TAI_1958_TO_UNIX_S = 378_691_200
_FINE_SCALE = float(1 << 24)

# big-endian structured layout of one packet (used by the encoder and the fast header check)
_PACKET_DTYPE = np.dtype(
    [
        ("hdr0", ">u2"),
        ("hdr1", ">u2"),
        ("length", ">u2"),
        ("coarse", ">u4"),
        ("fine", "u1", (3,)),
        ("b", ">f8", (3,)),
        ("q", ">f8", (4,)),
        ("temperature", ">f4"),
        ("mtq", ">f4", (3,)),
    ]
)
assert _PACKET_DTYPE.itemsize == PACKET_LENGTH


class PacketError(UnreadableInputError):
    """A packet stream that cannot be decoded at all (e.g. empty); HTTP 400, exit code 2."""


@dataclass(frozen=True)
class DecodedPackets:
    """Decoded magnetometer packets, one row per valid packet, in stream order.

    ``index`` holds each row's packet number in the stream (0-based); ``rejected`` lists
    ``(packet_number, reason)`` for packets that were truncated, of another APID or length.
    """

    index: np.ndarray  # (N,) int
    apid: np.ndarray  # (N,) int
    sequence_count: np.ndarray  # (N,) int
    t_tai_1958_s: np.ndarray  # (N,) float64 TAI seconds since 1958-01-01 TAI
    t_utc_s: np.ndarray  # (N,) float64 POSIX seconds of UTC
    b_raw_nt: np.ndarray  # (N, 3) sensor axes [nT]
    q_wxyz: np.ndarray  # (N, 4)
    temperature_c: np.ndarray  # (N,) [°C]
    mtq_am2: np.ndarray  # (N, 3) [A·m²]
    rejected: list[tuple[int, str]] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.index.shape[0])


def _tai_unix_to_utc_s(t_tai_unix_s: np.ndarray) -> np.ndarray:
    from orbitcal import timescales

    return np.asarray(timescales.to_utc_s(t_tai_unix_s, scale="TAI"), dtype=np.float64)


def _utc_s_to_tai_unix(t_utc_s: np.ndarray) -> np.ndarray:
    from orbitcal import timescales

    return np.asarray(timescales.utc_to_tai(t_utc_s), dtype=np.float64)


def _quiet_ccsdspy(record: logging.LogRecord) -> bool:
    return record.levelno >= logging.WARNING


def _ccsdspy_packet() -> object:
    # ccsdspy attaches a console handler and logs INFO on import; the library never prints.
    logger = logging.getLogger("ccsdspy")
    if _quiet_ccsdspy not in logger.filters:
        logger.addFilter(_quiet_ccsdspy)
    from ccsdspy import FixedLength, PacketField

    fields = [
        PacketField(name="coarse", data_type="uint", bit_length=32),
        PacketField(name="fine", data_type="uint", bit_length=24),
    ]
    fields += [PacketField(name=n, data_type="float", bit_length=64) for n in ("b_x", "b_y", "b_z")]
    fields += [
        PacketField(name=n, data_type="float", bit_length=64) for n in ("q_w", "q_x", "q_y", "q_z")
    ]
    fields += [
        PacketField(name=n, data_type="float", bit_length=32)
        for n in ("temperature", "mtq_x", "mtq_y", "mtq_z")
    ]
    return FixedLength(fields)


def _scan(
    data: bytes, apid: int | None, max_packets: int
) -> tuple[list[int], list[int], list[tuple[int, str]]]:
    """Walk the primary headers: offsets of good packets, their numbers, and rejections."""
    n_full, tail = divmod(len(data), PACKET_LENGTH)
    if n_full and tail == 0:
        # fast path: a whole number of packets whose headers all say "85 octets"
        arr = np.frombuffer(data, dtype=_PACKET_DTYPE, count=n_full)
        ok_len = arr["length"] == PACKET_LENGTH - 7
        ok_apid = np.ones(n_full, bool) if apid is None else (arr["hdr0"] & 0x7FF) == apid
        if bool(ok_len.all()) and bool(ok_apid.all()):
            idx = list(range(n_full))
            return [i * PACKET_LENGTH for i in idx], idx, []
    offsets: list[int] = []
    numbers: list[int] = []
    rejected: list[tuple[int, str]] = []
    reasons: dict[str, str] = {}  # one string per distinct reason, shared by its packets
    pos = 0
    number = 0
    while pos < len(data):
        if number >= max_packets:
            raise LimitExceededError(
                f"more than {max_packets:,} packets in the stream; the limit max_rows = "
                f"{max_packets:,}",
                limit_name="max_rows",
                limit=max_packets,
            )
        remaining = len(data) - pos
        if remaining < 6:
            rejected.append((number, f"truncated packet: {remaining} octets, header needs 6"))
            break
        hdr0 = int.from_bytes(data[pos : pos + 2], "big")
        total = int.from_bytes(data[pos + 4 : pos + 6], "big") + 7
        if remaining < total:
            rejected.append(
                (number, f"truncated packet: {remaining} of {total} octets (stream ends)")
            )
            break
        this_apid = hdr0 & 0x7FF
        why = ""
        if (hdr0 >> 13) != 0:
            why = f"packet version {hdr0 >> 13}, expected 0"
        elif total != PACKET_LENGTH:
            why = f"packet of {total} octets, the magnetometer layout has {PACKET_LENGTH}"
        elif apid is not None and this_apid != apid:
            why = f"APID {this_apid}, expected {apid}"
        if why:
            rejected.append((number, reasons.setdefault(why, why)))
        else:
            offsets.append(pos)
            numbers.append(number)
        pos += total
        number += 1
    return offsets, numbers, rejected


def decode_packets(
    data: bytes, *, apid: int | None = None, max_packets: int = 1_000_000
) -> DecodedPackets:
    """Decode a stream of magnetometer space packets (layout in the module docstring).

    Parameters
    ----------
    data : bytes
        Concatenated packets.
    apid : int, optional
        Accept only this APID (others are rejected with a reason); any APID when ``None``.
    max_packets : int
        Largest number of packets read (header walks included); more raises
        :class:`~orbitcal.errors.LimitExceededError` (limit ``max_rows``).

    Truncated packets, packets of another length or APID are reported in ``rejected`` by their
    0-based packet number; the valid ones are decoded.

    Raises
    ------
    PacketError
        No packets at all, or a stream the decoder could not read.
    LimitExceededError
        More than ``max_packets`` packets.
    """
    # ``data`` is untrusted (an upload) and goes through ccsdspy and numpy: what they raise on
    # hostile bytes that the scan did not foresee becomes a PacketError (logged as a reader bug).
    with reading_untrusted_input("packet stream", error=PacketError):
        return _decode_packets(data, apid, max_packets)


def _decode_packets(data: bytes, apid: int | None, max_packets: int) -> DecodedPackets:
    if not data:
        raise PacketError("no packets: the body is empty")
    if len(data) // PACKET_LENGTH > max_packets:
        raise LimitExceededError(
            f"{len(data) // PACKET_LENGTH:,} packets exceed the limit max_rows = {max_packets:,}",
            limit_name="max_rows",
            limit=max_packets,
        )
    offsets, numbers, rejected = _scan(data, apid, max_packets)
    n = len(offsets)
    if n == 0:
        empty = np.zeros(0)
        return DecodedPackets(
            index=np.zeros(0, int),
            apid=np.zeros(0, int),
            sequence_count=np.zeros(0, int),
            t_tai_1958_s=empty,
            t_utc_s=empty,
            b_raw_nt=np.zeros((0, 3)),
            q_wxyz=np.zeros((0, 4)),
            temperature_c=empty,
            mtq_am2=np.zeros((0, 3)),
            rejected=rejected,
        )
    if n * PACKET_LENGTH == len(data):
        good = data
    else:
        good = b"".join(data[o : o + PACKET_LENGTH] for o in offsets)
    packet = _ccsdspy_packet()
    cols = packet.load(io.BytesIO(good), include_primary_header=True)  # type: ignore[attr-defined]
    coarse = np.asarray(cols["coarse"], dtype=np.float64)
    fine = np.asarray(cols["fine"], dtype=np.float64)
    t_tai_1958 = coarse + fine / _FINE_SCALE
    t_utc = _tai_unix_to_utc_s(t_tai_1958 - TAI_1958_TO_UNIX_S)

    def stack(*names: str) -> np.ndarray:
        return np.stack([np.asarray(cols[c], dtype=np.float64) for c in names], axis=-1)

    # A CUC time before 1972 has no UTC (no leap-second offset defined): e.g. a zeroed time field
    # (1958-01-01 TAI). A TAI instant inside a leap second has no POSIX UTC time of its own (it
    # would merge with the next second). Both are rejected with the reason, never decoded as NaN.
    t_tai_unix = t_tai_1958 - TAI_1958_TO_UNIX_S
    no_utc = ~np.isfinite(t_utc)
    back = _utc_s_to_tai_unix(np.where(no_utc, 0.0, t_utc))
    in_leap = ~no_utc & (np.abs(back - t_tai_unix) > 1e-6)
    keep = ~(no_utc | in_leap)
    numbers_arr = np.asarray(numbers, dtype=int)
    if not keep.all():
        for k in np.flatnonzero(~keep).tolist():
            coarse_k = int(coarse[k])
            if no_utc[k]:
                why = (
                    f"CUC time {coarse_k} s + {int(fine[k])}/2^24 after 1958-01-01 TAI is before "
                    "1972-01-01, where UTC is not defined by leap seconds (a zeroed time field?)"
                )
            else:
                why = (
                    f"CUC time {coarse_k} s after 1958-01-01 TAI falls in a leap second "
                    "(23:59:60 UTC), which UTC seconds since 1970 cannot hold apart from the next "
                    "second"
                )
            rejected.append((int(numbers_arr[k]), why))
        rejected.sort()
    return DecodedPackets(
        index=numbers_arr[keep],
        apid=np.asarray(cols["CCSDS_APID"], dtype=int)[keep],
        sequence_count=np.asarray(cols["CCSDS_SEQUENCE_COUNT"], dtype=int)[keep],
        t_tai_1958_s=t_tai_1958[keep],
        t_utc_s=t_utc[keep],
        b_raw_nt=stack("b_x", "b_y", "b_z")[keep],
        q_wxyz=stack("q_w", "q_x", "q_y", "q_z")[keep],
        temperature_c=np.asarray(cols["temperature"], dtype=np.float64)[keep],
        mtq_am2=stack("mtq_x", "mtq_y", "mtq_z")[keep],
        rejected=rejected,
    )


def encode_packets(
    t_utc_s: np.ndarray,
    b_raw_nt: np.ndarray,
    *,
    q_wxyz: np.ndarray | None = None,
    temperature_c: np.ndarray | None = None,
    mtq_am2: np.ndarray | None = None,
    apid: int = DEFAULT_APID,
    first_sequence_count: int = 0,
) -> bytes:
    """Encode samples as magnetometer space packets (one per sample; NaN where not given).

    ``t_utc_s`` [POSIX s of UTC] is converted to TAI with the leap-second table, then to the CUC
    code (whole seconds and 24-bit fraction since 1958-01-01 TAI, fraction rounded to nearest).
    """
    t_utc_s = np.asarray(t_utc_s, dtype=np.float64)
    n = t_utc_s.shape[0]
    if not 0 <= apid < 2048:
        raise BadInputError(f"APID {apid} does not fit in 11 bits")
    t_tai_1958 = _utc_s_to_tai_unix(t_utc_s) + TAI_1958_TO_UNIX_S
    coarse = np.floor(t_tai_1958)
    fine = np.rint((t_tai_1958 - coarse) * _FINE_SCALE).astype(np.int64)
    carry = fine >= (1 << 24)
    coarse = coarse + carry
    fine = np.where(carry, fine - (1 << 24), fine)
    arr = np.zeros(n, dtype=_PACKET_DTYPE)
    arr["hdr0"] = (1 << 11) | apid  # version 0, type 0 (TM), secondary header present
    arr["hdr1"] = (0b11 << 14) | ((first_sequence_count + np.arange(n)) % (1 << 14))
    arr["length"] = PACKET_LENGTH - 7
    arr["coarse"] = coarse.astype(np.uint32)
    arr["fine"][:, 0] = (fine >> 16) & 0xFF
    arr["fine"][:, 1] = (fine >> 8) & 0xFF
    arr["fine"][:, 2] = fine & 0xFF
    arr["b"] = np.asarray(b_raw_nt, dtype=np.float64).reshape(n, 3)
    arr["q"] = np.nan if q_wxyz is None else np.asarray(q_wxyz, dtype=np.float64).reshape(n, 4)
    arr["temperature"] = np.nan if temperature_c is None else np.asarray(temperature_c)
    arr["mtq"] = np.nan if mtq_am2 is None else np.asarray(mtq_am2, dtype=np.float64).reshape(n, 3)
    return arr.tobytes()
