"""The black-box probe framework: a real ``orbitcal serve`` process and hostile requests against it.

A *probe* is one crafted request with what must come back: the HTTP status (never ≥ 500), words
the error message must contain, and how many samples the spacecraft holds afterwards. After each
probe the runner checks that the server process is still alive and answers ``/healthz``, and it
records the peak resident memory of the server during the probe (``VmHWM`` of
``/proc/<pid>/status``, reset before each probe through ``/proc/<pid>/clear_refs``).

Usage in a test module (see ``test_probes_parsing.py``)::

    from probes import Probe, ServeProcess, serve_process

    @pytest.fixture(scope="module")
    def server(tmp_path_factory):
        with serve_process(tmp_path_factory.mktemp("probes")) as s:
            yield s

    @pytest.mark.parametrize("probe", PROBES, ids=lambda p: p.name)
    def test_probe(server, probe):
        server.run(probe)            # asserts status, message, stored rows, liveness; records RSS

``serve_process(..., database="postgresql")`` runs the same server on a fresh PostgreSQL schema
(mark such tests ``services``; :func:`require_service` fails them in CI when the server is down).
Every probe's outcome is collected in :data:`RESULTS`; ``tests/reliability/conftest.py`` prints a
per-class summary (count, worst status, deaths, peak RSS) at the end of the run and writes it as
JSON to ``$ORBITCAL_PROBE_REPORT`` when that is set (the figures of ``docs/reliability.md``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import httpx
import numpy as np
import sqlalchemy as sa
from reliability_helpers import ADMIN_KEY, REPO, free_port, pid_alive, require_service

__all__ = [
    "PG_URL",
    "RESULTS",
    "Probe",
    "ProbeResult",
    "ServeProcess",
    "StoredSamples",
    "serve_process",
]

#: PostgreSQL of this machine kind (trust authentication, database ``test``).
PG_URL = os.environ.get("ORBITCAL_TEST_PG", "postgresql://postgres@127.0.0.1:5432/test")
TELEMETRY = "/v1/spacecraft/{sc}/telemetry"


@dataclass(frozen=True)
class Probe:
    """One crafted request and what must come back.

    Attributes
    ----------
    name : str
        Unique, readable id (used as the pytest id).
    klass : str
        The class of hostile input it belongs to (``"nesting"``, ``"gzip"``, …): the summary and
        ``docs/reliability.md`` report per class.
    body : bytes or callable returning bytes
        The request body (a callable builds a large body only when the probe runs).
    headers : mapping
        Request headers (``content-type``, ``content-encoding``, …); the admin key is added
        unless ``key`` says otherwise.
    status : int or tuple of int
        Accepted status code(s). A status ≥ 500 always fails the probe.
    says : tuple of str
        Substrings (case-insensitive) the response text must contain, e.g. the limit's name.
    stored : int or None
        Samples the probe's spacecraft must hold afterwards (a fresh spacecraft per probe unless
        ``spacecraft`` is given, then the *increase*); ``None`` skips the check.
    method, path, params : str, str, mapping
        The request; ``{sc}`` in ``path`` is replaced by the probe's spacecraft id.
    key : str or None
        ``X-API-Key`` to send; the admin key by default, ``None`` for no key.
    spacecraft : str or None
        Use this existing spacecraft instead of a fresh one.
    check : callable or None
        Extra check ``check(server, spacecraft_id, response)`` run after the built-in ones
        (e.g. that the stored values equal what was sent).
    """

    name: str
    klass: str
    body: bytes | Callable[[], bytes] = b""
    headers: Mapping[str, str] = field(default_factory=dict)
    status: int | tuple[int, ...] = 200
    says: tuple[str, ...] = ()
    stored: int | None = 0
    method: str = "POST"
    path: str = TELEMETRY
    params: Mapping[str, Any] = field(default_factory=dict)
    key: str | None = ADMIN_KEY
    spacecraft: str | None = None
    check: Callable[[ServeProcess, str, httpx.Response], None] | None = None

    def build_body(self) -> bytes:
        return self.body() if callable(self.body) else self.body


@dataclass
class ProbeResult:
    """What one probe produced (collected in :data:`RESULTS`)."""

    name: str
    klass: str
    database: str
    status: int
    detail: str
    stored: int
    body_bytes: int
    rss_before_mb: float
    peak_rss_mb: float
    seconds: float
    alive: bool
    failure: str = ""


#: Every probe run in this session, in order.
RESULTS: list[ProbeResult] = []


@dataclass(frozen=True)
class StoredSamples:
    """The stored samples of one spacecraft, time-ordered, read straight from the database."""

    t_utc_us: np.ndarray  # (N,) int64
    b_nt: np.ndarray  # (N, 3)
    hk: list[str | None]  # the stored housekeeping JSON per row


class ServeProcess:
    """A running ``orbitcal serve`` subprocess and a direct connection to its database."""

    def __init__(
        self, proc: subprocess.Popen[bytes], url: str, database_url: str, database: str, log: Path
    ) -> None:
        self.proc = proc
        self.pid = proc.pid
        self.url = url
        self.database_url = database_url
        self.database = database
        self.log = log
        self.engine = sa.create_engine(database_url, poolclass=sa.pool.NullPool)
        self._n = 0

    # --- process -------------------------------------------------------------------------------

    def alive(self) -> bool:
        return self.proc.poll() is None and pid_alive(self.pid)

    def healthy(self) -> bool:
        try:
            return httpx.get(self.url + "/healthz", timeout=30).status_code == 200
        except httpx.TransportError:
            return False

    def reset_peak_rss(self) -> None:
        """Reset the kernel's high-water mark of the server's resident memory (Linux ≥ 4.0)."""
        try:
            with open(f"/proc/{self.pid}/clear_refs", "w") as f:
                f.write("5")
        except OSError:  # pragma: no cover - not Linux, or not allowed: the peak stays cumulative
            pass

    def _status_mb(self, key: str) -> float:
        try:
            with open(f"/proc/{self.pid}/status") as f:
                for line in f:
                    if line.startswith(key):
                        return int(line.split()[1]) / 1024
        except OSError:
            pass
        return float("nan")

    def peak_rss_mb(self) -> float:
        """Peak resident memory of the server since the last reset [MiB] (``VmHWM``)."""
        return self._status_mb("VmHWM:")

    def rss_mb(self) -> float:
        """Resident memory of the server now [MiB] (``VmRSS``)."""
        return self._status_mb("VmRSS:")

    def log_text(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""

    # --- HTTP ----------------------------------------------------------------------------------

    def client(self, key: str | None = ADMIN_KEY, **kwargs: Any) -> httpx.Client:
        headers = {"X-API-Key": key} if key else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=120, **kwargs)

    def new_spacecraft(self, prefix: str = "probe", **fields: Any) -> str:
        """Register a fresh spacecraft (id ``<prefix>-<n>-<random>``) and return its id."""
        self._n += 1
        sc = f"{prefix}-{self._n:04d}-{uuid.uuid4().hex[:6]}"
        with self.client() as http:
            r = http.post("/v1/spacecraft", json={"id": sc, **fields})
        assert r.status_code == 201, r.text
        return sc

    # --- database ------------------------------------------------------------------------------

    def stored_count(self, spacecraft: str) -> int:
        """Samples stored for a spacecraft (counted in the samples table itself)."""
        with self.engine.connect() as conn:
            n = conn.execute(
                sa.text(
                    "SELECT COUNT(*) FROM samples s JOIN spacecraft c ON c.pk = s.spacecraft_pk "
                    "WHERE c.id = :sc"
                ),
                {"sc": spacecraft},
            ).scalar_one()
        return int(n)

    def stored_samples(self, spacecraft: str) -> StoredSamples:
        with self.engine.connect() as conn:
            rows = conn.execute(
                sa.text(
                    "SELECT s.t_utc_us, s.b_x, s.b_y, s.b_z, s.hk FROM samples s "
                    "JOIN spacecraft c ON c.pk = s.spacecraft_pk WHERE c.id = :sc "
                    "ORDER BY s.t_utc_us"
                ),
                {"sc": spacecraft},
            ).fetchall()
        t = np.array([r[0] for r in rows], dtype=np.int64)
        b = np.array([r[1:4] for r in rows], dtype=np.float64).reshape(-1, 3)
        return StoredSamples(t, b, [r[4] for r in rows])

    # --- probes --------------------------------------------------------------------------------

    def run(self, probe: Probe) -> ProbeResult:
        """Send one probe, then assert everything it promises (see :class:`Probe`)."""
        if probe.spacecraft is None:
            sc = self.new_spacecraft()
            before = 0
        else:
            sc = probe.spacecraft
            before = self.stored_count(sc)
        body = probe.build_body()
        headers = dict(probe.headers)
        if probe.key is not None:
            headers["X-API-Key"] = probe.key
        self.reset_peak_rss()
        rss_before = self.rss_mb()
        t0 = time.perf_counter()
        status, text = -1, ""
        try:
            with httpx.Client(base_url=self.url, timeout=120) as http:
                r = http.request(
                    probe.method,
                    probe.path.format(sc=sc),
                    content=body,
                    headers=headers,
                    params=dict(probe.params) or None,  # None: the path's own query stays
                )
            status, text = r.status_code, r.text
        except httpx.TransportError as exc:  # a dead server, or one that closed on us
            text = f"transport error: {type(exc).__name__}: {exc}"
            r = None
        seconds = time.perf_counter() - t0
        alive = self.alive() and self.healthy()
        peak = self.peak_rss_mb()
        stored = self.stored_count(sc) - before if alive else -1
        result = ProbeResult(
            name=probe.name,
            klass=probe.klass,
            database=self.database,
            status=status,
            detail=text[:500],
            stored=stored,
            body_bytes=len(body),
            rss_before_mb=rss_before,
            peak_rss_mb=peak,
            seconds=seconds,
            alive=alive,
        )
        RESULTS.append(result)
        try:
            assert alive, f"server process died or stopped answering: {self.log_text()[-2000:]}"
            assert 0 < status < 500, f"status {status}: {text[:500]}"
            expected = (probe.status,) if isinstance(probe.status, int) else probe.status
            assert status in expected, f"status {status}, expected {expected}: {text[:500]}"
            for word in probe.says:
                assert word.lower() in text.lower(), f"{word!r} not in the answer: {text[:500]}"
            if probe.stored is not None:
                assert stored == probe.stored, f"{stored} samples stored, expected {probe.stored}"
            if probe.check is not None:
                assert r is not None
                probe.check(self, sc, r)
        except AssertionError as exc:
            result.failure = str(exc)[:500]
            raise
        return result

    def close(self) -> None:
        self.engine.dispose()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)


@contextmanager
def _pg_schema() -> Iterator[str]:
    """A fresh PostgreSQL schema (dropped afterwards) and the URL whose search_path is it."""
    require_service("PostgreSQL", 5432)
    schema = "probe_" + uuid.uuid4().hex[:12]
    admin = sa.create_engine(PG_URL, poolclass=sa.pool.NullPool)
    with admin.begin() as conn:
        conn.exec_driver_sql(f"CREATE SCHEMA {schema}")
    sep = "&" if "?" in PG_URL else "?"
    try:
        yield f"{PG_URL}{sep}options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.exec_driver_sql(f"DROP SCHEMA IF EXISTS {schema} CASCADE")
        admin.dispose()


@contextmanager
def serve_process(
    work_dir: Path,
    *,
    database: Literal["sqlite", "postgresql"] = "sqlite",
    env: Mapping[str, str] | None = None,
    args: tuple[str, ...] = (),
    startup_timeout_s: float = 180.0,
) -> Iterator[ServeProcess]:
    """Run ``python -m orbitcal serve`` on a free loopback port until the block ends.

    Parameters
    ----------
    work_dir : Path
        Working directory of the server (its log ``serve.log`` and SQLite file go here).
    database : {"sqlite", "postgresql"}
        A fresh SQLite file, or a fresh schema of the PostgreSQL at :data:`PG_URL`.
    env : mapping, optional
        Extra ``ORBITCAL_*`` settings. By default the rate limit is off (probes measure parsing,
        not the limiter), the scheduler is off and the admin key is :data:`ADMIN_KEY`.
    args : tuple of str
        Extra ``orbitcal serve`` options.
    """
    with _pg_schema() if database == "postgresql" else _sqlite_url(work_dir) as database_url:
        port = free_port()
        log = work_dir / f"serve-{port}.log"
        child_env = {
            **os.environ,
            "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
            "ORBITCAL_ADMIN_KEY": ADMIN_KEY,
            "ORBITCAL_RATE_LIMIT_PER_S": "0",
            "ORBITCAL_LOG_LEVEL": "WARNING",
            "ORBITCAL_SQLITE_SYNCHRONOUS": "NORMAL",
            **(env or {}),
        }
        argv = [sys.executable, "-m", "orbitcal", "serve", "--port", str(port)]
        argv += ["--database", database_url, "--no-scheduler", *args]
        with open(log, "ab") as log_file:
            proc = subprocess.Popen(
                argv, cwd=work_dir, env=child_env, stdout=log_file, stderr=subprocess.STDOUT
            )
        server = ServeProcess(proc, f"http://127.0.0.1:{port}", database_url, database, log)
        try:
            deadline = time.monotonic() + startup_timeout_s
            while not server.healthy():
                if not server.alive():
                    raise RuntimeError(f"orbitcal serve exited: {server.log_text()[-3000:]}")
                if time.monotonic() > deadline:
                    raise RuntimeError(f"orbitcal serve not healthy in {startup_timeout_s:g} s")
                time.sleep(0.1)
            yield server
        finally:
            server.close()


@contextmanager
def _sqlite_url(work_dir: Path) -> Iterator[str]:
    yield f"sqlite:///{work_dir / ('probes-' + uuid.uuid4().hex[:8] + '.sqlite')}"


def summarize(results: list[ProbeResult]) -> list[dict[str, Any]]:
    """Per (class, database): probes, failures, deaths, ≥ 500 answers, worst body's peak RSS."""
    groups: dict[tuple[str, str], list[ProbeResult]] = {}
    for r in results:
        groups.setdefault((r.klass, r.database), []).append(r)
    rows = []
    for (klass, database), rs in sorted(groups.items()):

        def growth(r: ProbeResult) -> float:
            g = r.peak_rss_mb - r.rss_before_mb
            return g if np.isfinite(g) else -1.0

        worst = max(rs, key=growth)
        rows.append(
            {
                "class": klass,
                "database": database,
                "probes": len(rs),
                "failed": sum(bool(r.failure) for r in rs),
                "deaths": sum(not r.alive for r in rs),
                "status_5xx": sum(r.status >= 500 or r.status < 0 for r in rs),
                "statuses": sorted({r.status for r in rs}),
                "peak_rss_mb": round(worst.peak_rss_mb, 1),
                "peak_growth_mb": round(growth(worst), 1),
                "worst_probe": worst.name,
                "worst_body_bytes": worst.body_bytes,
                "max_seconds": round(max(r.seconds for r in rs), 3),
            }
        )
    return rows


def check_stored_equal(
    t_utc_us: np.ndarray, b_nt: np.ndarray
) -> Callable[[ServeProcess, str, httpx.Response], None]:
    """A :attr:`Probe.check`: the spacecraft holds exactly these samples (times [µs] and b [nT])."""

    def check(server: ServeProcess, sc: str, _r: httpx.Response) -> None:
        stored = server.stored_samples(sc)
        order = np.argsort(t_utc_us, kind="stable")
        np.testing.assert_array_equal(stored.t_utc_us, np.asarray(t_utc_us)[order])
        np.testing.assert_array_equal(stored.b_nt, np.asarray(b_nt).reshape(-1, 3)[order])

    return check
