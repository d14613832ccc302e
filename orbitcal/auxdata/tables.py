"""Installed and shipped auxiliary tables: where they live, which one is active, how to update.

A table kind (``leap_seconds``, ``eop``, ``rc_index``, ``kp``, ``dst``) is served from the per-user
data directory when a validated copy is installed there, and from the copy shipped with orbitcal
(or with its pinned dependencies) otherwise; whichever is valid further into the future wins.

Data directory: ``ORBITCAL_DATA_DIR`` if set, else the platform's user data directory
(``~/.local/share/orbitcal`` on Linux, via ``platformdirs`` when installed). It holds the files and
``manifest.json`` with, per kind, the source URL, retrieval time, sha256, format and coverage. An
offline site points ``ORBITCAL_DATA_DIR`` (or ``--data-dir``) at its own mirror, or runs
``orbitcal data update --url KIND=file:///mirror/...``.

:func:`update` downloads to a temporary file in that directory, validates it with the parser of
its kind (format, checksum where published, plausibility, coverage not older than the active
table), and only then renames it over the installed file (``os.replace``, atomic on POSIX); the
manifest is replaced the same way. A failed, truncated or malformed download never replaces a good
table.
"""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import json
import os
import re
import tempfile
import threading
import urllib.parse
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from orbitcal.auxdata.formats import PARSERS, ParsedTable, TableFormatError
from orbitcal.errors import BadInputError

__all__ = [
    "DEFAULT_URLS",
    "FILE_NAMES",
    "KINDS",
    "ActiveTable",
    "active_table",
    "data_dir",
    "generation",
    "reload",
    "shipped_table",
    "status",
    "update",
    "using",
]

#: Table kinds, in the order they are listed.
KINDS: tuple[str, ...] = ("leap_seconds", "eop", "rc_index", "kp", "dst")

#: File name of each kind inside the data directory.
FILE_NAMES = {
    "leap_seconds": "leap-seconds.list",
    "eop": "finals2000A.all",
    "rc_index": "RC_index.dat",
    "kp": "Kp_ap_since_1932.txt",
    "dst": "Dst_WDC.dat",
}

#: Authoritative sources. The RC URL is DTU Space's directory page, whose link containing
#: ``RC/current`` is the current file (as ``chaosmagpy.data_utils.load_RC_datfile`` finds it).
#: The Dst URL is a monthly template of WDC Kyoto's real-time Dst (WDC format); the last
#: ``DST_MONTHS`` months are fetched and joined.
DEFAULT_URLS = {
    "leap_seconds": "https://hpiers.obspm.fr/iers/bul/bulc/ntp/leap-seconds.list",
    "eop": "https://datacenter.iers.org/products/eop/rapid/standard/finals2000A.all",
    "rc_index": "http://www.spacecenter.dk/files/magnetic-models/RC/",
    "kp": "https://kp.gfz.de/app/files/Kp_ap_since_1932.txt",
    "dst": "https://wdc.kugi.kyoto-u.ac.jp/dst_realtime/{yyyy}{mm}/dst{yy}{mm}.for.request",
}

#: Months of Dst fetched by :func:`update` from a monthly template URL.
DST_MONTHS = 3

#: Largest file accepted [bytes] (finals2000A.all is ~3.5 MB, the RC index text ~10 MB).
MAX_BYTES = 64 * 1024 * 1024

_MANIFEST = "manifest.json"
_LOCK = threading.RLock()
_CACHE: dict[tuple[str, str], tuple[tuple[Any, ...], ActiveTable | None]] = {}
_SHIPPED: dict[str, ActiveTable | None] = {}
_GENERATION = [0]
_OVERRIDES: dict[str, ActiveTable] = {}


def _iso(t_utc_s: float | None) -> str | None:
    if t_utc_s is None:
        return None
    return datetime.fromtimestamp(float(t_utc_s), tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _now_s() -> float:
    return datetime.now(tz=UTC).timestamp()


@dataclass
class ActiveTable:
    """A validated table and where it came from.

    Attributes
    ----------
    parsed : ParsedTable
        The arrays and coverage.
    origin : {"installed", "shipped"}
    path : str
        The file read.
    source_url : str or None
        Where an installed copy was downloaded from; the package for a shipped one.
    retrieved_at : str or None
        ISO-8601 UTC of the download (installed), None for shipped copies.
    sha256 : str
    notes : list of str
    """

    parsed: ParsedTable
    origin: str
    path: str
    source_url: str | None
    retrieved_at: str | None
    sha256: str
    notes: list[str] = field(default_factory=list)

    @property
    def kind(self) -> str:
        return self.parsed.kind

    def describe(self) -> dict[str, Any]:
        """JSON-ready description: file, origin, source, retrieval, sha256, coverage."""
        p = self.parsed
        return {
            "file": Path(self.path).name,
            "origin": self.origin,
            "format": p.format,
            "source": self.source_url,
            "retrieved_at": self.retrieved_at,
            "sha256": self.sha256,
            "coverage_start": _iso(p.coverage_start_utc_s),
            "coverage_end": _iso(p.coverage_end_utc_s),
            "valid_until": _iso(p.valid_until_utc_s),
            "predictions_from": _iso(p.predictions_from_utc_s),
            "notes": [*p.notes, *self.notes],
        }


# --- locations ----------------------------------------------------------------------------------


def data_dir(path: str | os.PathLike[str] | None = None) -> Path:
    """The data directory: ``path``, else ``ORBITCAL_DATA_DIR``, else the user data directory."""
    if path is not None:
        return Path(path).expanduser()
    env = os.environ.get("ORBITCAL_DATA_DIR")
    if env:
        return Path(env).expanduser()
    try:
        import platformdirs

        return Path(platformdirs.user_data_dir("orbitcal", appauthor=False))
    except ImportError:  # pragma: no cover - platformdirs is normally present
        base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
        return Path(base) / "orbitcal"


def _sha256(raw: bytes) -> str:
    return hashlib.sha256(raw).hexdigest()


def read_manifest(directory: Path) -> dict[str, Any]:
    """The manifest of a data directory (``{"tables": {}}`` when there is none or it is bad)."""
    try:
        doc = json.loads((directory / _MANIFEST).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return {"tables": {}}
    if not isinstance(doc, dict) or not isinstance(doc.get("tables"), dict):
        return {"tables": {}}
    return doc


def _atomic_write(path: Path, raw: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# --- shipped copies -----------------------------------------------------------------------------


def _shipped_leap() -> ActiveTable:
    path = Path(str(resources.files("orbitcal.auxdata").joinpath("shipped", "leap-seconds.list")))
    raw = path.read_bytes()
    return ActiveTable(
        PARSERS["leap_seconds"](raw),
        "shipped",
        str(path),
        "orbitcal/auxdata/shipped (IERS leap-seconds.list, see README.md there)",
        None,
        _sha256(raw),
    )


def _shipped_eop() -> ActiveTable:
    """Skyfield's builtin UT1 − UTC (``skyfield/data/iers.npz``, built from finals2000A.all)."""
    import skyfield

    path = Path(str(resources.files("skyfield").joinpath("data", "iers.npz")))
    raw = path.read_bytes()
    arrays = np.load(path)
    daily_tt = arrays["tt_jd_minus_arange"] + np.arange(len(arrays["tt_jd_minus_arange"]))
    delta_t = (arrays["delta_t_1e7"] / 1e7).round(7)
    leap_jd = arrays["leap_dates"]
    leap_off = arrays["leap_offsets"]
    # The rows are at 0 h UTC and TT − UTC < 70 s, so the nearest whole MJD is the row's date.
    mjd = np.round(daily_tt - 2_400_000.5)
    before = np.searchsorted(leap_jd - 2_400_000.5, mjd, "right") - 1
    tai_utc = np.where(before >= 0, leap_off[np.clip(before, 0, None)], leap_off[0] - 1.0)
    tt_minus_utc = tai_utc + 32.184
    dut1 = np.round(tt_minus_utc - delta_t, 7)
    t = (mjd - 40_587.0) * 86_400.0
    # finals2000A.all carries one year of Bulletin A predictions after the last observed day; the
    # builtin arrays do not keep the I/P flags, so the boundary is inferred from that rule.
    pred_from = float(t[-1] - 365 * 86_400.0)
    n = mjd.size
    parsed = ParsedTable(
        kind="eop",
        format=f"Skyfield {skyfield.__version__} builtin iers.npz (from finals2000A.all)",
        coverage_start_utc_s=float(t[0]),
        coverage_end_utc_s=float(t[-1]),
        valid_until_utc_s=float(t[-1]),
        predictions_from_utc_s=pred_from,
        data={
            "mjd": mjd,
            "dut1_s": dut1,
            "x_arcsec": np.full(n, np.nan),
            "y_arcsec": np.full(n, np.nan),
            "dut1_predicted": t >= pred_from,
            "pm_predicted": np.zeros(n, dtype=bool),
        },
        notes=[
            "no polar motion in this table (taken as zero)",
            "prediction boundary inferred: the last 365 days of finals2000A.all are predictions",
        ],
    )
    return ActiveTable(
        parsed, "shipped", str(path), f"skyfield {skyfield.__version__} package", None, _sha256(raw)
    )


def _shipped_rc() -> ActiveTable:
    # The package's file and version without importing it (its import pulls in matplotlib.pyplot,
    # 0.4 s of every diagnosis).
    import importlib.metadata
    import importlib.util

    spec = importlib.util.find_spec("chaosmagpy")
    if spec is None or spec.origin is None:  # pragma: no cover - a pinned dependency
        raise ModuleNotFoundError("chaosmagpy is not installed: no shipped RC index")
    path = Path(spec.origin).parent / "lib" / "RC_index.h5"
    raw = path.read_bytes()
    return ActiveTable(
        PARSERS["rc_index"](raw),
        "shipped",
        str(path),
        f"chaosmagpy {importlib.metadata.version('chaosmagpy')} package",
        None,
        _sha256(raw),
    )


_SHIPPED_LOADERS = {"leap_seconds": _shipped_leap, "eop": _shipped_eop, "rc_index": _shipped_rc}


def shipped_table(kind: str) -> ActiveTable | None:
    """The copy shipped with orbitcal or its pinned dependencies; None for Kp and Dst."""
    _check_kind(kind)
    with _LOCK:
        if kind not in _SHIPPED:
            loader = _SHIPPED_LOADERS.get(kind)
            _SHIPPED[kind] = loader() if loader is not None else None
        return _SHIPPED[kind]


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise BadInputError(f"unknown table {kind!r}: use one of {', '.join(KINDS)}")


# --- installed copies ---------------------------------------------------------------------------


def _installed(kind: str, directory: Path) -> tuple[ActiveTable | None, str | None]:
    """The installed table, or (None, reason) when there is none or it no longer validates."""
    entry = read_manifest(directory)["tables"].get(kind)
    if not isinstance(entry, dict):
        return None, None
    path = directory / str(entry.get("file", FILE_NAMES[kind]))
    try:
        raw = path.read_bytes()
    except OSError as exc:
        return None, f"installed {kind} file unreadable ({exc})"
    digest = _sha256(raw)
    if digest != entry.get("sha256"):
        return None, f"installed {path.name} does not match its manifest sha256 (changed on disk)"
    try:
        parsed = PARSERS[kind](raw)
    except TableFormatError as exc:
        return None, f"installed {path.name} no longer validates: {exc}"
    return (
        ActiveTable(
            parsed,
            "installed",
            str(path),
            entry.get("source_url"),
            entry.get("retrieved_at"),
            digest,
        ),
        None,
    )


def active_table(
    kind: str, *, directory: str | os.PathLike[str] | None = None
) -> ActiveTable | None:
    """The table of ``kind`` in use: the installed or the shipped copy, whichever is valid longer.

    Cached per data directory and manifest state; :func:`reload` forgets the cache.
    """
    _check_kind(kind)
    override = _OVERRIDES.get(kind)
    if override is not None:
        return override
    d = data_dir(directory)
    try:
        st = (d / _MANIFEST).stat()
        stamp: tuple[Any, ...] = (st.st_mtime_ns, st.st_size, _GENERATION[0])
    except OSError:
        stamp = (None, None, _GENERATION[0])
    key = (kind, str(d))
    with _LOCK:
        hit = _CACHE.get(key)
        if hit is not None and hit[0] == stamp:
            return hit[1]
    installed, problem = _installed(kind, d)
    shipped = shipped_table(kind)
    chosen = installed
    if shipped is not None and (
        installed is None or shipped.parsed.valid_until_utc_s > installed.parsed.valid_until_utc_s
    ):
        chosen = shipped
    if chosen is not None and problem:
        chosen = ActiveTable(**{**chosen.__dict__, "notes": [*chosen.notes, problem]})
    with _LOCK:
        _CACHE[key] = (stamp, chosen)
    return chosen


@contextlib.contextmanager
def using(tables: dict[str, ParsedTable]) -> Iterator[None]:
    """Serve these tables instead of the installed/shipped ones inside the block (what-if runs:
    benchmarks comparing UT1 = UTC with the table, a pinned table for a reproduction).

    Not thread-safe across threads that compute meanwhile; the caches are reset on entry and exit.
    """
    for kind in tables:
        _check_kind(kind)
    saved = dict(_OVERRIDES)
    with _LOCK:
        for kind, parsed in tables.items():
            _OVERRIDES[kind] = ActiveTable(parsed, "override", f"<{parsed.format}>", None, None, "")
    reload()
    try:
        yield
    finally:
        with _LOCK:
            _OVERRIDES.clear()
            _OVERRIDES.update(saved)
        reload()


def generation() -> int:
    """A counter that changes whenever the tables may have changed (for callers' caches)."""
    return _GENERATION[0]


def reload() -> None:
    """Forget every cached table (after an update, or when ``ORBITCAL_DATA_DIR`` changes)."""
    with _LOCK:
        _CACHE.clear()
        _GENERATION[0] += 1
    import sys

    # Only modules already imported hold caches (looked up, not imported: no import cycle).
    timescales = sys.modules.get("orbitcal.timescales")
    if timescales is not None:
        timescales.reset_tables()
    field = sys.modules.get("orbitcal.field")
    if field is not None:  # get_field("RC") holds the RC index it was built with
        field.get_field.cache_clear()


# --- status -------------------------------------------------------------------------------------


def status(*, directory: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """What is installed and active per kind, and until when it is valid.

    Returns
    -------
    dict
        ``{"data_dir": str, "now": ISO, "tables": {kind: {"active": {...} | None, "installed":
        {...} | None, "shipped": {...} | None, "expired": bool, "problem": str | None}}}``.
    """
    d = data_dir(directory)
    now = _now_s()
    out: dict[str, Any] = {"data_dir": str(d), "now": _iso(now), "tables": {}}
    for kind in KINDS:
        installed, problem = _installed(kind, d)
        shipped = shipped_table(kind)
        active = active_table(kind, directory=d)
        out["tables"][kind] = {
            "active": active.describe() if active else None,
            "installed": installed.describe() if installed else None,
            "shipped": shipped.describe() if shipped else None,
            "expired": bool(active is not None and active.parsed.valid_until_utc_s < now),
            "problem": problem,
        }
    return out


# --- update -------------------------------------------------------------------------------------


def _fetch(url: str, timeout_s: float) -> tuple[bytes, str]:
    """GET ``url`` (http, https or file); returns the body and the final URL."""
    scheme = urllib.parse.urlparse(url).scheme
    if scheme not in ("http", "https", "file"):
        raise BadInputError(f"unsupported URL scheme {scheme!r} in {url}")
    with urllib.request.urlopen(url, timeout=timeout_s) as resp:
        declared = resp.headers.get("Content-Length") if hasattr(resp, "headers") else None
        raw = resp.read(MAX_BYTES + 1)
        final = resp.geturl()
    if len(raw) > MAX_BYTES:
        raise TableFormatError(f"{url}: larger than {MAX_BYTES} bytes")
    if declared is not None and declared.isdigit() and int(declared) != len(raw):
        raise TableFormatError(
            f"{url}: received {len(raw)} of {declared} bytes (connection cut, truncated)"
        )
    return raw, final


_HREF_RE = re.compile(rb"""href\s*=\s*["']([^"']+)["']""", re.IGNORECASE)


def _resolve_rc(url: str, timeout_s: float) -> str:
    """A directory page → the link holding ``RC/current`` (else the last ``.dat`` link)."""
    if not url.endswith("/"):
        return url
    page, final = _fetch(url, timeout_s)
    links = [h.decode("ascii", "replace") for h in _HREF_RE.findall(page)]
    pick = [h for h in links if "RC/current" in h] or [h for h in links if h.endswith(".dat")]
    if not pick:
        raise TableFormatError(f"{url}: no link to the current RC file on the page")
    return urllib.parse.urljoin(final, pick[0])


def _fetch_dst(template: str, timeout_s: float, now_s: float) -> tuple[bytes, str]:
    now = datetime.fromtimestamp(now_s, tz=UTC)
    parts: list[bytes] = []
    used: list[str] = []
    y, m = now.year, now.month
    months = []
    for _ in range(DST_MONTHS):
        months.append((y, m))
        y, m = (y, m - 1) if m > 1 else (y - 1, 12)
    for y, m in reversed(months):
        url = template.format(yyyy=f"{y:04d}", yy=f"{y % 100:02d}", mm=f"{m:02d}")
        try:
            raw, _ = _fetch(url, timeout_s)
        except OSError:
            if (y, m) == months[0]:
                continue  # the current month may not be published yet
            raise
        parts.append(raw.rstrip(b"\n") + b"\n")
        used.append(url)
    return b"".join(parts), " + ".join(used)


def update(
    *,
    directory: str | os.PathLike[str] | None = None,
    kinds: tuple[str, ...] | list[str] | None = None,
    urls: dict[str, str] | None = None,
    timeout_s: float = 60.0,
    now_utc_s: float | None = None,
) -> list[dict[str, Any]]:
    """Download, validate and install the auxiliary tables.

    Parameters
    ----------
    directory : path, optional
        Data directory (default :func:`data_dir`).
    kinds : sequence of str, optional
        Which tables (default all of :data:`KINDS`).
    urls : dict, optional
        Per-kind URL overriding :data:`DEFAULT_URLS` (a mirror, or ``file://`` paths).
    timeout_s : float
        Network timeout per request [s].
    now_utc_s : float, optional
        The retrieval time to record [POSIX s] (default now).

    Returns
    -------
    list of dict
        Per kind: ``{"kind", "status": "updated" | "unchanged" | "failed", "reason", "url",
        "table": {...}}``. A failed kind leaves the installed table as it was.
    """
    d = data_dir(directory)
    chosen = list(kinds) if kinds else list(KINDS)
    for k in chosen:
        _check_kind(k)
    now = _now_s() if now_utc_s is None else float(now_utc_s)
    sources = {**DEFAULT_URLS, **(urls or {})}
    results: list[dict[str, Any]] = []
    for kind in chosen:
        url = sources[kind]
        result: dict[str, Any] = {"kind": kind, "url": url}
        try:
            if kind == "dst" and "{" in url:
                raw, final = _fetch_dst(url, timeout_s, now)
            else:
                if kind == "rc_index":
                    url = _resolve_rc(url, timeout_s)
                raw, final = _fetch(url, timeout_s)
            result["url"] = final
            parsed = PARSERS[kind](raw)
            current = active_table(kind, directory=d)
            if current is not None and parsed.valid_until_utc_s < current.parsed.valid_until_utc_s:
                raise TableFormatError(
                    f"the downloaded {kind} table is valid until "
                    f"{_iso(parsed.valid_until_utc_s)}, earlier than the one in use "
                    f"({_iso(current.parsed.valid_until_utc_s)}, {current.origin}): kept the latter"
                )
            digest = _sha256(raw)
            if current is not None and current.origin == "installed" and current.sha256 == digest:
                result.update(status="unchanged", reason="same file as installed")
                results.append(result)
                continue
            expired = parsed.valid_until_utc_s < now
            entry = {
                "file": FILE_NAMES[kind],
                "source_url": final,
                "retrieved_at": _iso(now),
                "sha256": digest,
                "format": parsed.format,
                "coverage_start": _iso(parsed.coverage_start_utc_s),
                "coverage_end": _iso(parsed.coverage_end_utc_s),
                "valid_until": _iso(parsed.valid_until_utc_s),
                "predictions_from": _iso(parsed.predictions_from_utc_s),
            }
            with _LOCK:
                _atomic_write(d / FILE_NAMES[kind], raw)
                manifest = read_manifest(d)
                manifest["tables"][kind] = entry
                _atomic_write(
                    d / _MANIFEST, (json.dumps(manifest, indent=2) + "\n").encode("utf-8")
                )
            result.update(
                status="updated",
                reason="valid until "
                + str(entry["valid_until"])
                + (" (already expired)" if expired else ""),
                table=entry,
            )
        except (OSError, http.client.HTTPException, TableFormatError, ValueError) as exc:
            result.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
        results.append(result)
    reload()
    return results
