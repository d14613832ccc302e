"""Parsers and validators of the auxiliary tables, one per published format.

Every parser takes the file's bytes, checks the format, the physical plausibility and (where the
publisher gives one) the checksum, and returns a :class:`ParsedTable` with the coverage. Anything
wrong raises :class:`TableFormatError` naming the line and the reason, so a truncated, corrupt or
foreign file is never installed.

Formats
-------
``leap_seconds``
    IERS ``leap-seconds.list`` (NTP seconds, ``#$`` last update, ``#@`` expiry, ``#h`` SHA-1 of
    the data, https://hpiers.obspm.fr/iers/bul/bulc/ntp/leap-seconds.list) or IERS
    ``Leap_Second.dat`` (MJD, "File expires on DD Month YYYY").
``eop``
    IERS Rapid Service ``finals2000A.all`` / ``finals2000A.data`` (fixed columns, see
    https://datacenter.iers.org readme.finals2000A): UT1 − UTC, polar motion x, y, and the I/P flag
    that marks the predictions.
``rc_index``
    ChaosMagPy's ``RC_index.h5`` (HDF5 with ``time`` [MJD2000], ``RC_e``, ``RC_i`` [nT]).
``kp``
    GFZ Potsdam ``Kp_ap_since_1932.txt`` (3-hourly Kp).
``dst``
    WDC Kyoto Dst in the WDC format (``DSTyymm*dd``, 24 hourly values per line).
"""

from __future__ import annotations

import hashlib
import io
import re
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError

__all__ = [
    "PARSERS",
    "ParsedTable",
    "TableFormatError",
    "parse_dst_wdc",
    "parse_finals2000a",
    "parse_kp_gfz",
    "parse_leap_seconds",
    "parse_rc_index_h5",
]


_NTP_UNIX_OFFSET_S = 2_208_988_800.0  # 1900-01-01 → 1970-01-01
_MJD_UNIX_EPOCH = 40_587.0  # MJD of 1970-01-01
_MJD2000_UNIX_S = 946_684_800.0
_DAY_S = 86_400.0
_MONTHS = {
    m: i + 1
    for i, m in enumerate(
        [
            "january",
            "february",
            "march",
            "april",
            "may",
            "june",
            "july",
            "august",
            "september",
            "october",
            "november",
            "december",
        ]
    )
}


class TableFormatError(BadInputError):
    """A downloaded or mirrored table is not in its published format, fails its checksum, is
    truncated or carries implausible values; it is not installed."""


@dataclass
class ParsedTable:
    """A validated table.

    Attributes
    ----------
    kind : str
        ``leap_seconds``, ``eop``, ``rc_index``, ``kp`` or ``dst``.
    format : str
        Name of the recognised format.
    coverage_start_utc_s, coverage_end_utc_s : float
        First and last instant with data [POSIX s].
    valid_until_utc_s : float
        Until when the table may be used without extrapolation: the expiry of a leap-second list,
        the last row of an EOP or index table [POSIX s].
    predictions_from_utc_s : float or None
        EOP only: first instant whose UT1 − UTC is a prediction [POSIX s].
    data : dict
        The parsed arrays (kind-specific keys, see the parsers).
    notes : list of str
        Facts worth showing (checksum verified, missing polar motion, ...).
    """

    kind: str
    format: str
    coverage_start_utc_s: float
    coverage_end_utc_s: float
    valid_until_utc_s: float
    predictions_from_utc_s: float | None = None
    data: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _text(raw: bytes, what: str) -> str:
    if not raw:
        raise TableFormatError(f"{what}: the file is empty")
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise TableFormatError(
            f"{what}: not an ASCII text file (byte {exc.start} is {raw[exc.start]:#04x})"
        ) from exc


def _iso(t_utc_s: float) -> str:
    return datetime.fromtimestamp(t_utc_s, tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


# --- leap seconds -------------------------------------------------------------------------------


def _check_leap_steps(t_utc_s: FloatArray, offsets: FloatArray, what: str) -> None:
    if t_utc_s.size < 28:
        raise TableFormatError(
            f"{what}: {t_utc_s.size} leap-second rows; the 28 steps of 1972-2017 are missing "
            "(truncated file?)"
        )
    if t_utc_s[0] != 63_072_000.0 or offsets[0] != 10.0:
        raise TableFormatError(f"{what}: the first row must be 1972-01-01 with TAI - UTC = 10 s")
    if np.any(np.diff(t_utc_s) <= 0):
        raise TableFormatError(f"{what}: the leap-second dates are not increasing")
    if np.any(np.abs(np.diff(offsets)) != 1.0):
        raise TableFormatError(f"{what}: TAI - UTC must change by exactly 1 s per row")
    days = t_utc_s / _DAY_S
    if np.any(days != np.round(days)):
        raise TableFormatError(f"{what}: a leap second is not at 0 h UTC")


def _leap_seconds_list(text: str) -> ParsedTable:
    what = "leap-seconds.list"
    updated = expires = None
    digest = None
    parts: list[str] = []
    times: list[float] = []
    offsets: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if line.startswith("#$"):
            updated = line[2:].split()[0]
            parts.append(updated)
        elif line.startswith("#@"):
            expires = line[2:].split()[0]
            parts.append(expires)
        elif line.startswith("#h"):
            digest = "".join(f"{int(w, 16):08x}" for w in line[2:].split())
        elif line.strip() and not line.startswith("#"):
            fields = line.split("#")[0].split()
            if len(fields) < 2 or not (fields[0].isdigit() and fields[1].isdigit()):
                raise TableFormatError(f"{what} line {lineno}: expected 'NTP_SECONDS DTAI'")
            parts += fields[:2]
            times.append(float(fields[0]) - _NTP_UNIX_OFFSET_S)
            offsets.append(float(fields[1]))
    if updated is None or expires is None:
        raise TableFormatError(f"{what}: no '#$' last-update or '#@' expiry line")
    if digest is None:
        raise TableFormatError(f"{what}: no '#h' SHA-1 line (truncated file?)")
    computed = hashlib.sha1("".join(parts).encode("ascii"), usedforsecurity=False).hexdigest()
    if computed != digest:
        raise TableFormatError(
            f"{what}: SHA-1 of the data is {computed}, the file states {digest} (corrupt)"
        )
    t = np.asarray(times)
    off = np.asarray(offsets)
    _check_leap_steps(t, off, what)
    exp_s = float(expires) - _NTP_UNIX_OFFSET_S
    upd_s = float(updated) - _NTP_UNIX_OFFSET_S
    return ParsedTable(
        kind="leap_seconds",
        format="IERS leap-seconds.list",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=exp_s,
        valid_until_utc_s=exp_s,
        data={"t_utc_s": t, "tai_minus_utc_s": off, "updated_utc_s": upd_s},
        notes=[f"SHA-1 verified ({digest})", f"last update {_iso(upd_s)}"],
    )


_EXPIRES_RE = re.compile(r"File expires on\s+(\d{1,2})\s+([A-Za-z]+)\s+(\d{4})")


def _leap_second_dat(text: str) -> ParsedTable:
    what = "Leap_Second.dat"
    m = _EXPIRES_RE.search(text)
    if m is None:
        raise TableFormatError(f"{what}: no 'File expires on DD Month YYYY' line")
    month = _MONTHS.get(m.group(2).lower())
    if month is None:
        raise TableFormatError(f"{what}: unknown month {m.group(2)!r} in the expiry line")
    exp_s = datetime(int(m.group(3)), month, int(m.group(1)), tzinfo=UTC).timestamp()
    times: list[float] = []
    offsets: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = line.split()
        expected = f"{what} line {lineno}: expected 'MJD DAY MONTH YEAR TAI-UTC'"
        if len(fields) != 5:
            raise TableFormatError(expected)
        try:
            mjd = float(fields[0])
            offset = float(fields[4])
        except ValueError:
            raise TableFormatError(expected) from None
        times.append((mjd - _MJD_UNIX_EPOCH) * _DAY_S)
        offsets.append(offset)
    t = np.asarray(times)
    off = np.asarray(offsets)
    _check_leap_steps(t, off, what)
    return ParsedTable(
        kind="leap_seconds",
        format="IERS Leap_Second.dat",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=exp_s,
        valid_until_utc_s=exp_s,
        data={"t_utc_s": t, "tai_minus_utc_s": off},
        notes=["no checksum published for this format"],
    )


def parse_leap_seconds(raw: bytes) -> ParsedTable:
    """Leap seconds from ``leap-seconds.list`` (SHA-1 checked) or ``Leap_Second.dat``.

    ``data``: ``t_utc_s`` (N,) UTC instants from which ``tai_minus_utc_s`` (N,) holds [s].
    ``valid_until_utc_s`` is the published expiry.
    """
    text = _text(raw, "leap-second table")
    if "#@" in text or "#h" in text:
        return _leap_seconds_list(text)
    if "File expires on" in text:
        return _leap_second_dat(text)
    raise TableFormatError(
        "leap-second table: neither leap-seconds.list ('#@' expiry, '#h' SHA-1) nor "
        "Leap_Second.dat ('File expires on ...')"
    )


def write_leap_second_dat(t_utc_s: FloatArray, offsets: FloatArray, *, expires: str) -> str:
    """The IERS ``Leap_Second.dat`` text for a table (``expires`` as ``"28 June 2027"``)."""
    lines = [
        "#  Value of TAI-UTC in second valid beetween the initial value until",
        "#  the epoch given on the next line. The last line reads that NO",
        "#  leap second was introduced since the corresponding date",
        "#",
        f"#  File expires on {expires}",
        "#",
        "#    MJD        Date        TAI-UTC (s)",
        "#           day month year",
        "#    ---    --------------   ------",
        "#",
    ]
    for t, off in zip(t_utc_s, offsets, strict=True):
        d = datetime.fromtimestamp(float(t), tz=UTC)
        mjd = float(t) / _DAY_S + _MJD_UNIX_EPOCH
        lines.append(f"    {mjd:.1f}    {d.day:2d}  {d.month:2d} {d.year:4d}       {int(off)}")
    return "\n".join(lines) + "\n"


# --- EOP ----------------------------------------------------------------------------------------


def _field_float(line: str, a: int, b: int) -> float:
    s = line[a:b].strip()
    return float(s) if s else np.nan


def parse_finals2000a(raw: bytes) -> ParsedTable:
    """IERS ``finals2000A`` (Bulletin A columns): UT1 − UTC [s], polar motion x, y [arcsec].

    ``data``: ``mjd`` (N,) UTC, ``dut1_s``, ``x_arcsec``, ``y_arcsec`` (N,), ``dut1_predicted``
    and ``pm_predicted`` (N,) bool (the I/P flags). Rows without UT1 − UTC (the file's future
    dates) are dropped. ``predictions_from_utc_s`` is the first row flagged P for UT1.
    """
    what = "finals2000A"
    text = _text(raw, what)
    mjd: list[float] = []
    dut1: list[float] = []
    xs: list[float] = []
    ys: list[float] = []
    pflag: list[bool] = []
    pmflag: list[bool] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if len(line) < 68:
            if len(line.rstrip()) <= 16:  # a date with no values yet (end of the file)
                continue
            if line[57:58].strip() == "" and len(line.rstrip()) < 58:
                continue
            raise TableFormatError(f"{what} line {lineno}: {len(line)} characters, expected ≥ 68")
        try:
            m = float(line[7:15])
            d = _field_float(line, 58, 68)
            x = _field_float(line, 18, 27)
            y = _field_float(line, 37, 46)
        except ValueError:
            raise TableFormatError(
                f"{what} line {lineno}: MJD (cols 8-15), PM (19-27, 38-46) or UT1-UTC (59-68) "
                "is not a number"
            ) from None
        if np.isnan(d):
            continue
        flag = line[57]
        if flag not in "IP":
            raise TableFormatError(f"{what} line {lineno}: UT1 flag {flag!r} is neither I nor P")
        mjd.append(m)
        dut1.append(d)
        xs.append(x)
        ys.append(y)
        pflag.append(flag == "P")
        pmflag.append(line[16] == "P")
    if len(mjd) < 30:
        raise TableFormatError(f"{what}: {len(mjd)} rows with UT1 - UTC (truncated file?)")
    mjd_a = np.asarray(mjd)
    dut1_a = np.asarray(dut1)
    steps = np.diff(mjd_a)
    if np.any(steps != 1.0):
        i = int(np.argmax(steps != 1.0))
        raise TableFormatError(f"{what}: rows are not daily after MJD {mjd_a[i]:.0f}")
    if np.any(np.abs(dut1_a) > 0.95):
        i = int(np.argmax(np.abs(dut1_a) > 0.95))
        raise TableFormatError(
            f"{what}: |UT1 - UTC| = {abs(dut1_a[i])} s > 0.9 s at MJD {mjd_a[i]}"
        )
    jumps = np.abs(np.diff(dut1_a))
    if np.any((jumps > 0.01) & (np.abs(jumps - 1.0) > 0.01)):
        i = int(np.argmax((jumps > 0.01) & (np.abs(jumps - 1.0) > 0.01)))
        raise TableFormatError(f"{what}: UT1 - UTC jumps by {jumps[i]:.4f} s at MJD {mjd_a[i]}")
    x_a, y_a = np.asarray(xs), np.asarray(ys)
    if np.any(np.abs(x_a[np.isfinite(x_a)]) > 1.0) or np.any(np.abs(y_a[np.isfinite(y_a)]) > 1.0):
        raise TableFormatError(f"{what}: a polar-motion value exceeds 1 arcsec")
    p = np.asarray(pflag)
    t = (mjd_a - _MJD_UNIX_EPOCH) * _DAY_S
    pred_from = float(t[int(np.argmax(p))]) if p.any() else None
    notes = []
    if pred_from is not None:
        notes.append(f"UT1 - UTC predicted from {_iso(pred_from)} (Bulletin A, flag P)")
    return ParsedTable(
        kind="eop",
        format="IERS finals2000A",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=float(t[-1]),
        valid_until_utc_s=float(t[-1]),
        predictions_from_utc_s=pred_from,
        data={
            "mjd": mjd_a,
            "dut1_s": dut1_a,
            "x_arcsec": x_a,
            "y_arcsec": y_a,
            "dut1_predicted": p,
            "pm_predicted": np.asarray(pmflag),
        },
        notes=notes,
    )


# --- RC index -----------------------------------------------------------------------------------


def parse_rc_index_h5(raw: bytes) -> ParsedTable:
    """ChaosMagPy's ``RC_index.h5``: ``time`` [MJD2000], ``RC_e``, ``RC_i`` [nT], hourly.

    ``data``: ``time_mjd2000``, ``rc_e_nt``, ``rc_i_nt`` (finite rows only).
    """
    import h5py

    what = "RC_index.h5"
    if not raw.startswith(b"\x89HDF\r\n\x1a\n"):
        return _rc_index_dat(raw)
    try:
        with h5py.File(io.BytesIO(raw), "r") as f:
            missing = [k for k in ("time", "RC_e", "RC_i") if k not in f]
            if missing:
                raise TableFormatError(f"{what}: lacks dataset(s) {', '.join(missing)}")
            time = np.asarray(f["time"][:], dtype=np.float64).ravel()
            rc_e = np.asarray(f["RC_e"][:], dtype=np.float64).ravel()
            rc_i = np.asarray(f["RC_i"][:], dtype=np.float64).ravel()
    except TableFormatError:
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise TableFormatError(f"{what}: unreadable HDF5 ({exc}; truncated?)") from exc
    if not (time.size == rc_e.size == rc_i.size):
        raise TableFormatError(f"{what}: time, RC_e and RC_i differ in length")
    ok = np.isfinite(time) & np.isfinite(rc_e) & np.isfinite(rc_i)
    return _rc_table(time[ok], rc_e[ok], rc_i[ok], what, "ChaosMagPy RC_index.h5")


def _rc_index_dat(raw: bytes) -> ParsedTable:
    """DTU's published RC text file: ``time [MJD2000] RC RC_e RC_i flag`` rows, ``#`` comments."""
    what = "RC index (.dat)"
    text = _text(raw, what)
    rows: list[tuple[float, float, float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#")[0].strip()
        if not body:
            continue
        f = body.split()
        expected = (
            f"{what} line {lineno}: expected 'time RC RC_e RC_i flag' (an HDF5 or DTU text file)"
        )
        if len(f) < 4:
            raise TableFormatError(expected)
        try:
            rows.append((float(f[0]), float(f[2]), float(f[3])))
        except ValueError:
            raise TableFormatError(expected) from None
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(arr), axis=1)
    arr = arr[ok]
    return _rc_table(arr[:, 0], arr[:, 1], arr[:, 2], what, "DTU RC index (text)")


def _rc_table(
    time: FloatArray, rc_e: FloatArray, rc_i: FloatArray, what: str, fmt: str
) -> ParsedTable:
    if time.size < 48:
        raise TableFormatError(f"{what}: {time.size} finite rows (truncated file?)")
    if np.any(np.diff(time) <= 0):
        raise TableFormatError(f"{what}: time is not increasing")
    if np.any(np.abs(rc_e) > 2000) or np.any(np.abs(rc_i) > 2000):
        raise TableFormatError(f"{what}: an RC value exceeds 2000 nT")
    t = time * _DAY_S + _MJD2000_UNIX_S
    return ParsedTable(
        kind="rc_index",
        format=fmt,
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=float(t[-1]),
        valid_until_utc_s=float(t[-1]),
        data={"time_mjd2000": time, "rc_e_nt": rc_e, "rc_i_nt": rc_i},
    )


# --- Kp, Dst ------------------------------------------------------------------------------------


def parse_kp_gfz(raw: bytes) -> ParsedTable:
    """GFZ ``Kp_ap_since_1932.txt``: ``YYYY MM DD hh.h hh._m days days_m Kp ap D`` rows.

    ``data``: ``t_start_utc_s`` (N,) start of each 3-hour interval, ``kp`` (N,); rows with
    Kp = −1 (not yet available) are dropped.
    """
    what = "Kp (GFZ)"
    text = _text(raw, what)
    starts: list[float] = []
    kps: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        expected = f"{what} line {lineno}: expected 'YYYY MM DD hh.h hh._m days days_m Kp ap D'"
        if len(f) != 10:
            raise TableFormatError(expected)
        try:
            y, mo, d = int(f[0]), int(f[1]), int(f[2])
            hour = float(f[3])
            kp = float(f[7])
            t0 = datetime(y, mo, d, tzinfo=UTC).timestamp() + hour * 3600.0
        except ValueError:
            raise TableFormatError(expected) from None
        if kp < 0:
            continue
        if kp > 9.0:
            raise TableFormatError(f"{what} line {lineno}: Kp = {kp} > 9")
        starts.append(t0)
        kps.append(kp)
    if len(starts) < 8:
        raise TableFormatError(f"{what}: {len(starts)} rows (truncated file?)")
    t = np.asarray(starts)
    if np.any(np.diff(t) <= 0):
        raise TableFormatError(f"{what}: times are not increasing")
    return ParsedTable(
        kind="kp",
        format="GFZ Kp_ap_since_1932",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=float(t[-1] + 3 * 3600.0),
        valid_until_utc_s=float(t[-1] + 3 * 3600.0),
        data={"t_start_utc_s": t, "kp": np.asarray(kps)},
    )


def parse_dst_wdc(raw: bytes) -> ParsedTable:
    """WDC Kyoto Dst in the WDC exchange format (120 columns per day).

    ``data``: ``t_start_utc_s`` (N,) start of each hour, ``dst_nt`` (N,) [nT]; 9999 (missing)
    is dropped.
    """
    what = "Dst (WDC format)"
    text = _text(raw, what)
    starts: list[float] = []
    values: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if not line.startswith("DST") or len(line.rstrip()) < 116 or line[7] != "*":
            raise TableFormatError(
                f"{what} line {lineno}: expected 'DSTyymm*dd' and 24 hourly values in 120 columns"
            )
        try:
            century = line[14:16].strip() or "19"
            year = int(century) * 100 + int(line[3:5])
            day0 = datetime(year, int(line[5:7]), int(line[8:10]), tzinfo=UTC).timestamp()
            base = int(line[16:20].strip() or "0")
            hourly = [int(line[20 + 4 * h : 24 + 4 * h]) for h in range(24)]
        except ValueError:
            raise TableFormatError(
                f"{what} line {lineno}: a date or value is not a number"
            ) from None
        for h, v in enumerate(hourly):
            if v == 9999:
                continue
            starts.append(day0 + 3600.0 * h)
            values.append(float(base * 100 + v))
    if len(starts) < 24:
        raise TableFormatError(f"{what}: {len(starts)} hourly values (truncated file?)")
    t = np.asarray(starts)
    order = np.argsort(t, kind="stable")
    t = t[order]
    dst = np.asarray(values)[order]
    if np.any(np.diff(t) <= 0):
        raise TableFormatError(f"{what}: a day appears twice")
    if np.any(np.abs(dst) > 2000):
        raise TableFormatError(f"{what}: a Dst value exceeds 2000 nT")
    return ParsedTable(
        kind="dst",
        format="WDC Kyoto Dst",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=float(t[-1] + 3600.0),
        valid_until_utc_s=float(t[-1] + 3600.0),
        data={"t_start_utc_s": t, "dst_nt": dst},
    )


#: Parser of each table kind.
PARSERS = {
    "leap_seconds": parse_leap_seconds,
    "eop": parse_finals2000a,
    "rc_index": parse_rc_index_h5,
    "kp": parse_kp_gfz,
    "dst": parse_dst_wdc,
}
