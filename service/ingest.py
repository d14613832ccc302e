"""Ingest: request body (any supported content type) → validated columns → database rows."""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import orjson
import pandas as pd

from orbitcal import ccsds
from orbitcal.errors import LimitExceededError, UnreadableInputError
from orbitcal.telemetry import RowError, Telemetry, TelemetryError, from_frame, parse_telemetry

__all__ = [
    "CCSDS_MEDIA_TYPE",
    "MEDIA_TYPES",
    "BodyTooLargeError",
    "ParsedUpload",
    "decompress",
    "parse_body",
    "telemetry_row_batches",
    "telemetry_to_rows",
]

#: Media type of a stream of magnetometer space packets (layout: ``docs/ccsds.md``).
CCSDS_MEDIA_TYPE = "application/vnd.ccsds.space-packet"

#: Accepted ``Content-Type`` → format name.
MEDIA_TYPES: dict[str, str] = {
    "text/csv": "csv",
    "application/x-ndjson": "ndjson",
    "application/json": "json",
    "application/vnd.apache.parquet": "parquet",
    CCSDS_MEDIA_TYPE: "ccsds",
}


class BodyTooLargeError(LimitExceededError):
    """The (decompressed) body exceeds the configured limit ``max_body_bytes`` (HTTP 413)."""

    def __init__(self, limit: int) -> None:
        super().__init__(
            f"decompressed body exceeds {limit} bytes (max_body_bytes)",
            limit_name="max_body_bytes",
            limit=limit,
        )


def _bad_encoding(message: str) -> UnreadableInputError:
    return UnreadableInputError(message, field="Content-Encoding")


@dataclass(frozen=True)
class ParsedUpload:
    telemetry: Telemetry
    rejected: list[RowError]


def decompress(body: bytes, encoding: str, *, limit: int) -> bytes:
    """Undo ``Content-Encoding: gzip|deflate`` without ever holding more than ``limit`` bytes.

    The compressed stream must be whole: it must end exactly where the body ends (no truncated
    stream, no trailing bytes). Several gzip members (RFC 1952 allows them) are all read, and
    their total counts against ``limit``. Anything else raises, so nothing of a damaged body is
    ever parsed or stored.

    Raises
    ------
    BodyTooLargeError
        The decompressed body exceeds ``limit`` bytes (HTTP 413).
    UnreadableInputError
        Unsupported encoding, or a corrupt, truncated or trailing-garbage stream (HTTP 400,
        naming the ``Content-Encoding`` field).
    """
    codings = [c.strip().lower() for c in encoding.split(",") if c.strip()]
    codings = [c for c in codings if c != "identity"]
    if not codings:
        return body
    if len(codings) > 1:
        raise _bad_encoding(
            f"Content-Encoding {encoding!r}: only one coding (gzip or deflate) is supported"
        )
    coding = {"x-gzip": "gzip"}.get(codings[0], codings[0])
    if coding not in ("gzip", "deflate"):
        raise _bad_encoding(
            f"Content-Encoding {coding!r} is not supported; use gzip, deflate or none"
        )
    if not body:
        raise _bad_encoding(f"body is empty but declares Content-Encoding {coding}")
    wbits = 16 + zlib.MAX_WBITS if coding == "gzip" else zlib.MAX_WBITS
    out: list[bytes] = []
    size = 0
    rest = body
    member = 0
    while True:
        d = zlib.decompressobj(wbits)
        try:
            chunk = d.decompress(rest, limit - size + 1)
        except zlib.error as exc:
            raise _bad_encoding(
                f"body is not valid {coding} (member {member + 1}): {exc}"
            ) from None
        size += len(chunk)
        if size > limit or d.unconsumed_tail:
            raise BodyTooLargeError(limit)
        out.append(chunk)
        if not d.eof:
            raise _bad_encoding(
                f"{coding} stream is truncated: it ends before its end marker and checksum "
                f"(member {member + 1}); nothing was stored"
            )
        rest = d.unused_data
        if not rest:
            return b"".join(out)
        if coding == "gzip" and rest[:2] == b"\x1f\x8b":
            member += 1  # another gzip member: read it too
            continue
        raise _bad_encoding(
            f"{len(rest)} bytes follow the end of the {coding} stream: the body must end where "
            "the compressed data ends; nothing was stored"
        )


def _packets_to_frame(decoded: ccsds.DecodedPackets) -> pd.DataFrame:
    cols: dict[str, Any] = {"time": decoded.t_utc_s}
    for i, c in enumerate(("b_x", "b_y", "b_z")):
        cols[c] = decoded.b_raw_nt[:, i]
    # NaN in an optional group of every packet means "not available": the column is left out.
    if not np.isnan(decoded.q_wxyz).all():
        for i, c in enumerate(("q_w", "q_x", "q_y", "q_z")):
            cols[c] = decoded.q_wxyz[:, i]
    if not np.isnan(decoded.temperature_c).all():
        cols["temperature"] = decoded.temperature_c
    if not np.isnan(decoded.mtq_am2).all():
        for i, c in enumerate(("mtq_x", "mtq_y", "mtq_z")):
            cols[c] = decoded.mtq_am2[:, i]
    return pd.DataFrame(cols)


def parse_body(body: bytes, *, fmt: str, time_scale: str, apid: int | None = None) -> ParsedUpload:
    """Validate an upload; row numbers in ``rejected`` are 0-based rows (packets for CCSDS).

    Raises ``TelemetryError`` / ``ccsds.PacketError`` (HTTP 400) when nothing can be read at all,
    ``LimitExceededError`` (413) beyond a parsing limit; the service's one handler answers them.
    """
    if fmt != "ccsds":
        result = parse_telemetry(body, fmt=fmt, time_scale=time_scale)  # type: ignore[arg-type]
        return ParsedUpload(result.telemetry, list(result.rejected))
    if time_scale.upper() != "UTC":
        raise TelemetryError("CCSDS packets carry TAI (CUC) times: leave time_scale out or use UTC")
    decoded = ccsds.decode_packets(body, apid=apid)
    rejected = [RowError(i, reason) for i, reason in decoded.rejected]
    if len(decoded) == 0:
        return ParsedUpload(Telemetry(t_utc_s=np.empty(0), b_raw_nt=np.empty((0, 3))), rejected)
    result = from_frame(_packets_to_frame(decoded), time_scale="UTC")
    rejected += [RowError(int(decoded.index[e.row]), e.reason) for e in result.rejected]
    rejected.sort(key=lambda e: e.row)
    return ParsedUpload(result.telemetry, rejected)


def _col(a: np.ndarray | None, n: int) -> list[Any]:
    return [None] * n if a is None else a.tolist()


def telemetry_to_rows(spacecraft_pk: int, tel: Telemetry) -> list[tuple[Any, ...]]:
    """Rows ``(spacecraft_pk, t_utc_us, *SAMPLE_COLUMNS, hk)`` for :func:`insert_samples`."""
    n = int(tel.t_utc_s.shape[0])
    if n == 0:
        return []
    t_us = np.rint(tel.t_utc_s * 1e6).astype(np.int64).tolist()
    b = tel.b_raw_nt
    q = tel.q_wxyz
    r = tel.r_itrs_km
    mtq = tel.mtq_am2
    columns: list[list[Any]] = [
        [spacecraft_pk] * n,
        t_us,
        b[:, 0].tolist(),
        b[:, 1].tolist(),
        b[:, 2].tolist(),
        *(_col(None if q is None else q[:, i], n) for i in range(4)),
        *(_col(None if r is None else r[:, i], n) for i in range(3)),
        _col(tel.temperature_c, n),
        *(_col(None if mtq is None else mtq[:, i], n) for i in range(3)),
    ]
    if tel.hk:
        names = list(tel.hk)
        values = [tel.hk[k].tolist() for k in names]
        columns.append(
            [
                orjson.dumps(dict(zip(names, vs, strict=True))).decode()
                for vs in zip(*values, strict=True)
            ]
        )
    else:
        columns.append([None] * n)
    return list(zip(*columns, strict=True))


#: Rows converted to Python tuples at a time (bounds the memory of a large upload's insert).
INSERT_BATCH_ROWS = 50_000


def telemetry_row_batches(
    spacecraft_pk: int, tel: Telemetry, batch_rows: int = INSERT_BATCH_ROWS
) -> Iterator[list[tuple[Any, ...]]]:
    """:func:`telemetry_to_rows` in slices of ``batch_rows`` (insert them in one transaction)."""
    for start in range(0, len(tel), batch_rows):
        yield telemetry_to_rows(spacecraft_pk, tel.select(slice(start, start + batch_rows)))


#: Valid rows an upload needs before a unit mistake refuses it whole (fewer: a warning only).
PLAUSIBILITY_MIN_ROWS = 20


def check_upload_plausible(tel: Telemetry, spacecraft: Any) -> str | None:
    """Whether the upload's median |B| can be the Earth's field in nT at the spacecraft's
    altitude (:mod:`orbitcal.plausibility`; the radius from the table's positions, else from the
    spacecraft's elements).

    Raises :class:`~orbitcal.plausibility.ImplausibleInputError` (422) for a recognisable unit
    mistake (Tesla, Gauss, µT, …) in an upload of at least :data:`PLAUSIBILITY_MIN_ROWS` valid
    rows; returns the reason, for the answer's ``warnings``, when the magnitude is implausible
    otherwise (or the upload is small); None when it is plausible. The retraining refuses such
    data in any case.
    """
    from orbitcal.plausibility import (
        ImplausibleInputError,
        elements_radius_km,
        field_scale_problem,
    )

    if len(tel) == 0:
        return None
    if tel.r_itrs_km is not None:
        r_km: float | None = float(np.median(np.linalg.norm(tel.r_itrs_km, axis=1)))
    else:
        r_km = elements_radius_km(
            getattr(spacecraft, "tle", None), getattr(spacecraft, "omm", None)
        )
    why = field_scale_problem(tel.b_raw_nt, r_km=r_km)
    if why is not None and len(tel) >= PLAUSIBILITY_MIN_ROWS and "looks like" in why:
        raise ImplausibleInputError(f"nothing was stored: {why}", field="b_x,b_y,b_z")
    return why
