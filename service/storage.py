"""Storage: SQLAlchemy 2 tables, engine factory, migrations and the bulk operations of the service.

The same code runs on SQLite (WAL, the embedded default) and PostgreSQL. Samples are keyed
by ``(spacecraft_pk, t_utc_us)``: the primary key is at once the idempotency constraint (a second
sample at the same time for the same spacecraft changes nothing and is counted as a duplicate) and
the index behind per-spacecraft time-range reads (a clustered ``WITHOUT ROWID`` b-tree on
SQLite, a b-tree primary-key index on PostgreSQL). Time is stored as integer microseconds of
UTC (Unix convention, leap seconds not counted) so that equality is exact.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import TYPE_CHECKING, Any

import numpy as np
import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

if TYPE_CHECKING:
    from orbitcal.telemetry import Telemetry

__all__ = [
    "SAMPLE_COLUMNS",
    "ApiKey",
    "Base",
    "Calibration",
    "CommitOutcomeUnknown",
    "DataAudit",
    "HealthPoint",
    "IngestLog",
    "Job",
    "Quarantine",
    "ResourceExhausted",
    "RetrainLock",
    "Sample",
    "SampleArrays",
    "Spacecraft",
    "acquire_lock",
    "bump_data_revision",
    "count_samples",
    "delete_samples",
    "find_window",
    "hash_key",
    "insert_samples",
    "log_upload",
    "make_engine",
    "normalise_url",
    "read_samples",
    "read_tx",
    "read_window",
    "release_lock",
    "resource_problem",
    "sample_times",
    "upgrade",
    "write_tx",
]


class Base(DeclarativeBase):
    pass


class Spacecraft(Base):
    __tablename__ = "spacecraft"

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    id: Mapped[str] = mapped_column(sa.String(64), unique=True, nullable=False)
    tle: Mapped[str | None] = mapped_column(sa.Text, nullable=True)
    omm: Mapped[dict[str, Any] | None] = mapped_column(sa.JSON, nullable=True)
    attitude_frame: Mapped[str] = mapped_column(sa.String(8), nullable=False, default="GCRS")
    #: Per-spacecraft overrides of the retraining schedule (cadence_s, min_new_samples, window_s).
    schedule: Mapped[dict[str, Any] | None] = mapped_column(sa.JSON, nullable=True)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    #: Samples stored so far (maintained in the ingest transaction).
    sample_count: Mapped[int] = mapped_column(sa.BigInteger, nullable=False, default=0)
    #: ``sample_count`` when the last retraining job was created (scheduler's "new samples").
    samples_at_last_job: Mapped[int] = mapped_column(sa.BigInteger, nullable=False, default=0)
    last_job_at: Mapped[float | None] = mapped_column(sa.Float, nullable=True)
    #: Bumped by :func:`bump_data_revision` whenever the stored samples change (ingest of new
    #: rows, delete, quarantine, release): the key of every cached answer computed from them.
    data_revision: Mapped[int] = mapped_column(
        sa.BigInteger, nullable=False, default=0, server_default="0"
    )


class Sample(Base):
    __tablename__ = "samples"
    __table_args__ = ({"sqlite_with_rowid": False},)

    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), primary_key=True
    )
    t_utc_us: Mapped[int] = mapped_column(sa.BigInteger, primary_key=True)
    b_x: Mapped[float] = mapped_column(sa.Float, nullable=False)
    b_y: Mapped[float] = mapped_column(sa.Float, nullable=False)
    b_z: Mapped[float] = mapped_column(sa.Float, nullable=False)
    q_w: Mapped[float | None] = mapped_column(sa.Float)
    q_x: Mapped[float | None] = mapped_column(sa.Float)
    q_y: Mapped[float | None] = mapped_column(sa.Float)
    q_z: Mapped[float | None] = mapped_column(sa.Float)
    r_x: Mapped[float | None] = mapped_column(sa.Float)
    r_y: Mapped[float | None] = mapped_column(sa.Float)
    r_z: Mapped[float | None] = mapped_column(sa.Float)
    temperature: Mapped[float | None] = mapped_column(sa.Float)
    mtq_x: Mapped[float | None] = mapped_column(sa.Float)
    mtq_y: Mapped[float | None] = mapped_column(sa.Float)
    mtq_z: Mapped[float | None] = mapped_column(sa.Float)
    hk: Mapped[str | None] = mapped_column(sa.Text)  # JSON object text of hk_<name> channels


class Calibration(Base):
    __tablename__ = "calibrations"
    __table_args__ = (sa.UniqueConstraint("spacecraft_pk", "version"),)

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False
    )
    version: Mapped[int] = mapped_column(sa.Integer, nullable=False)
    #: in_service | rejected | superseded
    status: Mapped[str] = mapped_column(sa.String(16), nullable=False)
    reason: Mapped[str | None] = mapped_column(sa.Text)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    job_id: Mapped[str | None] = mapped_column(sa.String(32))
    holdout_rms_nt: Mapped[float | None] = mapped_column(sa.Float)
    document: Mapped[dict[str, Any]] = mapped_column(sa.JSON, nullable=False)
    provenance: Mapped[dict[str, Any]] = mapped_column(sa.JSON, nullable=False)


class Job(Base):
    __tablename__ = "jobs"

    id: Mapped[str] = mapped_column(sa.String(32), primary_key=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False, index=True
    )
    kind: Mapped[str] = mapped_column(sa.String(16), nullable=False, default="retrain")
    trigger: Mapped[str] = mapped_column(sa.String(16), nullable=False, default="api")
    #: queued | running | succeeded | failed
    status: Mapped[str] = mapped_column(sa.String(16), nullable=False)
    error: Mapped[str | None] = mapped_column(sa.Text)
    params: Mapped[dict[str, Any]] = mapped_column(sa.JSON, nullable=False)
    result: Mapped[dict[str, Any] | None] = mapped_column(sa.JSON)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    started_at: Mapped[float | None] = mapped_column(sa.Float)
    finished_at: Mapped[float | None] = mapped_column(sa.Float)


class RetrainLock(Base):
    """One row per spacecraft being retrained: the primary key makes the lock exclusive."""

    __tablename__ = "retrain_locks"

    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), primary_key=True
    )
    job_id: Mapped[str] = mapped_column(sa.String(32), nullable=False)
    acquired_at: Mapped[float] = mapped_column(sa.Float, nullable=False)


class Quarantine(Base):
    """A time range of one spacecraft's samples kept out of retraining and diagnosis.

    Reversible: releasing sets ``released_at``/``released_by`` and the samples count again.
    """

    __tablename__ = "quarantines"

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False, index=True
    )
    start_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)  # UTC µs, inclusive
    end_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)  # UTC µs, inclusive
    reason: Mapped[str] = mapped_column(sa.Text, nullable=False, default="")
    created_by: Mapped[str] = mapped_column(sa.String(128), nullable=False)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    #: Samples in the range when it was quarantined.
    n_samples: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    released_at: Mapped[float | None] = mapped_column(sa.Float)
    released_by: Mapped[str | None] = mapped_column(sa.String(128))


class DataAudit(Base):
    """Who changed which stored samples, when: quarantine, release, delete (append-only)."""

    __tablename__ = "data_audit"

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False, index=True
    )
    #: quarantine | release | delete
    action: Mapped[str] = mapped_column(sa.String(16), nullable=False)
    start_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    end_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    n_samples: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    who: Mapped[str] = mapped_column(sa.String(128), nullable=False)
    at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    quarantine_pk: Mapped[int | None] = mapped_column(sa.Integer)
    reason: Mapped[str | None] = mapped_column(sa.Text)


class HealthPoint(Base):
    """One scored batch of a spacecraft's new samples against a calibration (service.health)."""

    __tablename__ = "health_points"
    __table_args__ = (
        sa.UniqueConstraint("spacecraft_pk", "start_us", "version", "kind"),
        sa.Index("ix_health_points_sc_end", "spacecraft_pk", "end_us"),
    )

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False
    )
    #: the calibration version scored
    version: Mapped[int] = mapped_column(sa.Integer, nullable=False)
    #: ``new`` (an upload's new samples) | ``holdout`` (the version's own held-out block)
    kind: Mapped[str] = mapped_column(sa.String(16), nullable=False)
    start_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)  # UTC µs of the batch
    end_us: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    n: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    rms_nt: Mapped[float] = mapped_column(sa.Float, nullable=False)
    noise_nt: Mapped[float | None] = mapped_column(sa.Float, nullable=True)
    #: the version's held-out RMS the rule compares with
    ref_rms_nt: Mapped[float] = mapped_column(sa.Float, nullable=False)
    cusum: Mapped[float] = mapped_column(sa.Float, nullable=False)
    stale: Mapped[bool] = mapped_column(sa.Boolean, nullable=False)
    #: on the point that raised the alarm: when the change began [UTC µs]
    change_at_us: Mapped[int | None] = mapped_column(sa.BigInteger, nullable=True)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)


class ApiKey(Base):
    __tablename__ = "api_keys"

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    #: sha256 hex of the key; the key itself is never stored.
    key_hash: Mapped[str] = mapped_column(sa.String(64), unique=True, nullable=False)
    prefix: Mapped[str] = mapped_column(sa.String(12), nullable=False)
    name: Mapped[str] = mapped_column(sa.String(128), nullable=False)
    scopes: Mapped[list[str]] = mapped_column(sa.JSON, nullable=False)
    created_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    revoked: Mapped[bool] = mapped_column(sa.Boolean, nullable=False, default=False)


class IngestLog(Base):
    """One row per telemetry upload: how many rows it had accepted, duplicated and rejected."""

    __tablename__ = "ingest_log"

    pk: Mapped[int] = mapped_column(sa.Integer, primary_key=True, autoincrement=True)
    spacecraft_pk: Mapped[int] = mapped_column(
        sa.Integer, sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"), nullable=False, index=True
    )
    received_at: Mapped[float] = mapped_column(sa.Float, nullable=False)
    fmt: Mapped[str] = mapped_column(sa.String(16), nullable=False)
    accepted: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    duplicates: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    rejected: Mapped[int] = mapped_column(sa.BigInteger, nullable=False)
    #: The first few rejected rows: ``[{"row": i, "reason": "..."}]``.
    examples: Mapped[list[dict[str, Any]] | None] = mapped_column(sa.JSON, nullable=True)


#: Rejected rows kept as examples per upload in ``ingest_log``.
INGEST_LOG_EXAMPLES = 5


def log_upload(
    conn: Connection,
    spacecraft_pk: int,
    *,
    fmt: str,
    accepted: int,
    duplicates: int,
    rejected: list[tuple[int, str]],
) -> None:
    """Record one upload in ``ingest_log`` (the dashboard's rejected-rows plot reads it)."""
    conn.execute(
        sa.insert(IngestLog).values(
            spacecraft_pk=spacecraft_pk,
            received_at=time.time(),
            fmt=fmt,
            accepted=accepted,
            duplicates=duplicates,
            rejected=len(rejected),
            examples=[{"row": r, "reason": why} for r, why in rejected[:INGEST_LOG_EXAMPLES]],
        )
    )


def hash_key(key: str) -> str:
    """sha256 hex digest of an API key (keys are ≥ 256-bit random, so no slow hash is needed)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


# ---------------------------------------------------------------------------------------------
# Engine and migrations


def normalise_url(url: str) -> str:
    """Use psycopg 3 for PostgreSQL URLs given without a driver."""
    if url.startswith("postgres://"):
        url = "postgresql://" + url[len("postgres://") :]
    if url.startswith("postgresql://"):
        url = "postgresql+psycopg://" + url[len("postgresql://") :]
    return url


def make_engine(url: str, *, sqlite_synchronous: str = "FULL", sqlite_max_bytes: int = 0) -> Engine:
    """Engine with WAL, a busy timeout and foreign keys on SQLite; pre-ping on PostgreSQL.

    ``sqlite_max_bytes`` > 0 caps the SQLite file (``PRAGMA max_page_count``): a write beyond it
    fails as on a full disk ("database or disk is full").
    """
    url = normalise_url(url)
    if url.startswith("sqlite"):
        engine = sa.create_engine(
            url,
            connect_args={"check_same_thread": False, "timeout": 30.0},
            poolclass=sa.pool.QueuePool,
            pool_size=8,
            max_overflow=16,
        )

        @event.listens_for(engine, "connect")
        def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
            # Let SQLAlchemy drive transactions (BEGIN) explicitly.
            dbapi_conn.isolation_level = None
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute(f"PRAGMA synchronous={sqlite_synchronous}")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            if sqlite_max_bytes > 0:
                page_size = int(cur.execute("PRAGMA page_size").fetchone()[0])
                cur.execute(f"PRAGMA max_page_count={max(1, sqlite_max_bytes // page_size)}")
            cur.close()

        @event.listens_for(engine, "begin")
        def _sqlite_begin(conn: Connection) -> None:
            # Writers take the write lock up front (no lock upgrade deadlocks); readers don't.
            immediate = conn.get_execution_options().get("write", False)
            conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")

        return engine
    return sa.create_engine(url, pool_pre_ping=True, pool_size=8, max_overflow=16)


def upgrade(engine: Engine) -> None:
    """Bring the schema to the newest Alembic revision (serialised across processes)."""
    from alembic import command
    from alembic.config import Config

    ini = resources.files("service").joinpath("alembic.ini")
    cfg = Config(str(ini))
    cfg.set_main_option("script_location", str(resources.files("service").joinpath("migrations")))
    with engine.connect() as conn:
        if conn.dialect.name == "postgresql":
            conn.exec_driver_sql("SELECT pg_advisory_lock(727272)")
            conn.commit()
        try:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
            conn.commit()
        finally:
            if conn.dialect.name == "postgresql":
                conn.exec_driver_sql("SELECT pg_advisory_unlock(727272)")
                conn.commit()


# ---------------------------------------------------------------------------------------------
# Samples

SAMPLE_COLUMNS: tuple[str, ...] = (
    "b_x",
    "b_y",
    "b_z",
    "q_w",
    "q_x",
    "q_y",
    "q_z",
    "r_x",
    "r_y",
    "r_z",
    "temperature",
    "mtq_x",
    "mtq_y",
    "mtq_z",
)


def _insert_sql(dialect: str) -> str:
    cols = ("spacecraft_pk", "t_utc_us", *SAMPLE_COLUMNS, "hk")
    mark = "?" if dialect == "sqlite" else "%s"
    return (
        f"INSERT INTO samples ({', '.join(cols)}) VALUES ({', '.join([mark] * len(cols))}) "
        "ON CONFLICT (spacecraft_pk, t_utc_us) DO NOTHING"
    )


def insert_samples(conn: Connection, spacecraft_pk: int, rows: Sequence[tuple[Any, ...]]) -> int:
    """Insert ``(spacecraft_pk, t_utc_us, *SAMPLE_COLUMNS, hk)`` rows; return how many were new.

    Runs inside the caller's transaction; rows whose time is already stored change nothing.
    """
    if not rows:
        return 0
    dbapi = conn.connection.driver_connection
    assert dbapi is not None
    cur = dbapi.cursor()
    try:
        cur.executemany(_insert_sql(conn.dialect.name), rows)
        inserted = int(cur.rowcount)
    finally:
        cur.close()
    if inserted < 0:  # driver could not tell: count the stored rows of this batch instead
        raise RuntimeError("database driver did not report the inserted row count")
    if inserted:
        conn.execute(
            sa.update(Spacecraft)
            .where(Spacecraft.pk == spacecraft_pk)
            .values(
                sample_count=Spacecraft.sample_count + inserted,
                data_revision=Spacecraft.data_revision + 1,
            )
        )
    return inserted


def bump_data_revision(conn: Connection, spacecraft_pk: int) -> None:
    """Mark the spacecraft's stored samples as changed (inside the caller's write transaction).

    Call it from every operation that changes which samples a computation would read —
    :func:`insert_samples` does for new rows; deleting, quarantining or releasing samples must
    too. Cached answers computed from the samples (the diagnosis) are keyed on the counter.
    """
    conn.execute(
        sa.update(Spacecraft)
        .where(Spacecraft.pk == spacecraft_pk)
        .values(data_revision=Spacecraft.data_revision + 1)
    )


@dataclass(frozen=True)
class SampleArrays:
    """Stored samples of one spacecraft, columnar, time-ordered."""

    t_utc_s: np.ndarray  # (N,) POSIX seconds of UTC
    columns: dict[str, np.ndarray]  # SAMPLE_COLUMNS -> (N,) float64, NaN where absent
    hk: dict[str, np.ndarray]  # hk_<name> -> (N,) float64, NaN where absent

    def __len__(self) -> int:
        return int(self.t_utc_s.shape[0])

    def has(self, *names: str) -> np.ndarray:
        """``(N,)`` bool: rows where every one of the columns ``names`` is present."""
        out = np.ones(len(self), dtype=bool)
        for c in names:
            out &= ~np.isnan(self.columns[c])
        return out

    def select(self, mask: np.ndarray) -> SampleArrays:
        """The rows picked by a boolean mask (still time-ordered)."""
        return SampleArrays(
            self.t_utc_s[mask],
            {k: v[mask] for k, v in self.columns.items()},
            {k: v[mask] for k, v in self.hk.items()},
        )

    def to_telemetry(self) -> Telemetry:
        """The rows as a :class:`~orbitcal.telemetry.Telemetry` (an optional group of columns is
        kept when every row has it; choose rows first, e.g. with :meth:`has`)."""
        from orbitcal.telemetry import Telemetry

        def group(*names: str) -> np.ndarray | None:
            block = np.stack([self.columns[c] for c in names], axis=-1)
            return None if np.isnan(block).any() else block

        temp = group("temperature")
        return Telemetry(
            t_utc_s=self.t_utc_s,
            b_raw_nt=group("b_x", "b_y", "b_z") if len(self) else np.zeros((0, 3)),  # type: ignore[arg-type]
            q_wxyz=group("q_w", "q_x", "q_y", "q_z"),
            r_itrs_km=group("r_x", "r_y", "r_z"),
            temperature_c=None if temp is None else temp[:, 0],
            mtq_am2=group("mtq_x", "mtq_y", "mtq_z"),
            hk={k: v for k, v in self.hk.items() if not np.isnan(v).any()},
        )


def read_samples(
    conn: Connection,
    spacecraft_pk: int,
    *,
    start_utc_s: float | None = None,
    end_utc_s: float | None = None,
    limit: int | None = None,
    include_quarantined: bool = False,
) -> SampleArrays:
    """Time-ordered samples in ``[start, end]`` (an index range scan on the primary key).

    Samples in an active quarantine are left out unless ``include_quarantined``.
    """
    cols = ", ".join(("t_utc_us", *SAMPLE_COLUMNS, "hk"))
    sql = f"SELECT {cols} FROM samples WHERE spacecraft_pk = :pk"
    where, params = _range_sql(spacecraft_pk, start_utc_s, end_utc_s, include_quarantined)
    sql += where + " ORDER BY t_utc_us"
    if limit is not None:
        sql += " LIMIT :limit"
        params["limit"] = int(limit)
    rows = conn.execute(sa.text(sql), params).all()
    n = len(rows)
    if n == 0:
        return SampleArrays(np.zeros(0), {c: np.zeros(0) for c in SAMPLE_COLUMNS}, {})
    numeric = np.array([r[: 1 + len(SAMPLE_COLUMNS)] for r in rows], dtype=np.float64)
    t = numeric[:, 0] / 1e6
    columns = {c: numeric[:, i + 1] for i, c in enumerate(SAMPLE_COLUMNS)}
    hk: dict[str, np.ndarray] = {}
    for i, r in enumerate(rows):
        text = r[-1]
        if not text:
            continue
        for name, value in json.loads(text).items():
            if name not in hk:
                hk[name] = np.full(n, np.nan)
            with contextlib.suppress(TypeError, ValueError):
                hk[name][i] = float(value)
    return SampleArrays(t, columns, hk)


def _range_sql(
    spacecraft_pk: int,
    start_utc_s: float | None,
    end_utc_s: float | None,
    include_quarantined: bool,
) -> tuple[str, dict[str, Any]]:
    sql = ""
    params: dict[str, Any] = {"pk": spacecraft_pk}
    if start_utc_s is not None:
        sql += " AND t_utc_us >= :start"
        params["start"] = round(start_utc_s * 1e6)
    if end_utc_s is not None:
        sql += " AND t_utc_us <= :end"
        params["end"] = round(end_utc_s * 1e6)
    if not include_quarantined:
        sql += (
            " AND NOT EXISTS (SELECT 1 FROM quarantines q WHERE q.spacecraft_pk = :pk"
            " AND q.released_at IS NULL AND samples.t_utc_us BETWEEN q.start_us AND q.end_us)"
        )
    return sql, params


def sample_times(conn: Connection, spacecraft_pk: int) -> np.ndarray:
    """Times of the spacecraft's samples outside active quarantines, ascending [s, POSIX UTC]."""
    where, params = _range_sql(spacecraft_pk, None, None, False)
    rows = conn.execute(
        sa.text(f"SELECT t_utc_us FROM samples WHERE spacecraft_pk = :pk{where} ORDER BY t_utc_us"),
        params,
    ).scalars()
    return np.fromiter(rows, dtype=np.int64).astype(np.float64) / 1e6


def count_samples(
    conn: Connection,
    spacecraft_pk: int,
    *,
    start_utc_s: float | None = None,
    end_utc_s: float | None = None,
    include_quarantined: bool = True,
) -> int:
    """Samples stored in ``[start, end]`` (all, or only those outside active quarantines)."""
    where, params = _range_sql(spacecraft_pk, start_utc_s, end_utc_s, include_quarantined)
    return int(
        conn.execute(
            sa.text(f"SELECT COUNT(*) FROM samples WHERE spacecraft_pk = :pk{where}"), params
        ).scalar_one()
    )


def _dense_latest_window(
    conn: Connection, spacecraft_pk: int, window_s: float, min_samples: int, limit_utc_s: float
) -> Any:
    """The common case of :func:`orbitcal.pipeline.training_window` by index lookups alone: the
    window ending at the latest sample not in the future, when it is dense (else None)."""
    from orbitcal.pipeline import Window

    where, params = _range_sql(spacecraft_pk, None, limit_utc_s, False)
    latest_us = conn.execute(
        sa.text(f"SELECT MAX(t_utc_us) FROM samples WHERE spacecraft_pk = :pk{where}"), params
    ).scalar_one_or_none()
    if latest_us is None:
        return None
    end = latest_us / 1e6
    n = count_samples(
        conn, spacecraft_pk, start_utc_s=end - window_s, end_utc_s=end, include_quarantined=False
    )
    if n < max(1, min_samples):
        return None
    where, params = _range_sql(spacecraft_pk, None, None, False)
    params["limit"] = round(limit_utc_s * 1e6)
    n_future = conn.execute(
        sa.text(
            f"SELECT COUNT(*) FROM samples WHERE spacecraft_pk = :pk AND t_utc_us > :limit{where}"
        ),
        params,
    ).scalar_one()
    return Window(end - window_s, end, n, {"future": int(n_future)} if n_future else {})


def find_window(
    conn: Connection,
    spacecraft_pk: int,
    *,
    window_s: float,
    min_samples: int,
    now_utc_s: float,
) -> Any:
    """The window of samples a retraining would read now (times only, no sample read)."""
    from orbitcal.pipeline import FUTURE_TOLERANCE_S, training_window

    window = _dense_latest_window(
        conn, spacecraft_pk, window_s, min_samples, now_utc_s + FUTURE_TOLERANCE_S
    )
    if window is None:  # the latest stretch is sparse: scan every sample time
        window = training_window(
            sample_times(conn, spacecraft_pk),
            window_s=window_s,
            min_samples=min_samples,
            now_utc_s=now_utc_s,
        )
    return window


def read_window(
    conn: Connection,
    spacecraft_pk: int,
    *,
    window_s: float,
    min_samples: int,
    now_utc_s: float,
) -> tuple[Any, SampleArrays]:
    """The recent window of samples outside quarantine, chosen robustly
    (:func:`orbitcal.pipeline.training_window`): ``(window, samples)``.

    ``window.excluded`` also counts the quarantined samples inside the window.
    """
    from orbitcal.pipeline import Window

    window = find_window(
        conn, spacecraft_pk, window_s=window_s, min_samples=min_samples, now_utc_s=now_utc_s
    )
    if window.end_utc_s is None:
        return window, SampleArrays(np.zeros(0), {c: np.zeros(0) for c in SAMPLE_COLUMNS}, {})
    samples = read_samples(
        conn, spacecraft_pk, start_utc_s=window.start_utc_s, end_utc_s=window.end_utc_s
    )
    quarantined = count_samples(
        conn, spacecraft_pk, start_utc_s=window.start_utc_s, end_utc_s=window.end_utc_s
    ) - len(samples)
    if quarantined:
        window = Window(
            window.start_utc_s,
            window.end_utc_s,
            window.n,
            {**window.excluded, "quarantined": quarantined},
        )
    return window, samples


def delete_samples(conn: Connection, spacecraft_pk: int, start_us: int, end_us: int) -> int:
    """Delete the samples in ``[start_us, end_us]`` (quarantined or not); return how many.

    Keeps ``sample_count`` and ``data_revision`` in step, inside the caller's transaction.
    """
    deleted = conn.execute(
        sa.delete(Sample).where(
            Sample.spacecraft_pk == spacecraft_pk,
            Sample.t_utc_us >= start_us,
            Sample.t_utc_us <= end_us,
        )
    ).rowcount
    n = int(deleted or 0)
    if n:
        conn.execute(
            sa.update(Spacecraft)
            .where(Spacecraft.pk == spacecraft_pk)
            .values(sample_count=Spacecraft.sample_count - n)
        )
    bump_data_revision(conn, spacecraft_pk)
    return n


# ---------------------------------------------------------------------------------------------
# Retraining lock


def acquire_lock(conn: Connection, spacecraft_pk: int, job_id: str, *, timeout_s: float) -> bool:
    """Take the spacecraft's retraining lock for ``job_id``; steal it only when abandoned."""
    now = time.time()
    conn.execute(
        sa.delete(RetrainLock).where(
            RetrainLock.spacecraft_pk == spacecraft_pk, RetrainLock.acquired_at < now - timeout_s
        )
    )
    dialect = conn.dialect.name
    if dialect == "postgresql":
        from sqlalchemy.dialects.postgresql import insert as pg_insert

        stmt: Any = pg_insert(RetrainLock).on_conflict_do_nothing()
    else:
        from sqlalchemy.dialects.sqlite import insert as sqlite_insert

        stmt = sqlite_insert(RetrainLock).on_conflict_do_nothing()
    conn.execute(stmt.values(spacecraft_pk=spacecraft_pk, job_id=job_id, acquired_at=now))
    holder = conn.execute(
        sa.select(RetrainLock.job_id).where(RetrainLock.spacecraft_pk == spacecraft_pk)
    ).scalar_one_or_none()
    return holder == job_id


def release_lock(conn: Connection, spacecraft_pk: int, job_id: str) -> None:
    conn.execute(
        sa.delete(RetrainLock).where(
            RetrainLock.spacecraft_pk == spacecraft_pk, RetrainLock.job_id == job_id
        )
    )


class CommitOutcomeUnknown(sa.exc.SQLAlchemyError):
    """The database connection was lost while COMMIT was in flight.

    The server may have made the transaction durable before it went away, so the caller cannot
    tell whether it was stored: re-sending is the safe answer (ingest is idempotent by
    (spacecraft, time)). Raised instead of the driver's error only for failures of COMMIT itself;
    a failure before it means nothing was stored.
    """


class ResourceExhausted(sa.exc.SQLAlchemyError):
    """The database failed for want of a resource of this machine: nothing was stored.

    ``resource`` names it for the operator: ``"disk"`` (ENOSPC, EDQUOT, SQLite "database or disk
    is full", PostgreSQL 53100), ``"file size limit"`` (EFBIG: the process's RLIMIT_FSIZE, which
    SQLite reports as an I/O error), ``"open files"`` (EMFILE/ENFILE) or ``"database connections"``
    (PostgreSQL 53300). The server answered the failing statement or COMMIT, so the
    transaction was rolled back (unlike :class:`CommitOutcomeUnknown`).
    """

    def __init__(self, resource: str, message: str) -> None:
        super().__init__(message)
        self.resource = resource


#: PostgreSQL SQLSTATEs of class 53 (insufficient resources) and what runs out.
_PG_RESOURCE_STATES = {
    "53100": "disk",
    "53200": "memory",
    "53300": "database connections",
}
#: The resource named when a write fails against this process's RLIMIT_FSIZE (EFBIG).
FILE_SIZE_LIMIT = "file size limit"
#: Resources whose exhaustion is the storage's (HTTP 507 Insufficient Storage, not 503).
STORAGE_RESOURCES = frozenset({"disk", FILE_SIZE_LIMIT})
_ERRNO_RESOURCES = {
    errno.ENOSPC: "disk",
    errno.EDQUOT: "disk",
    errno.EFBIG: FILE_SIZE_LIMIT,
    errno.EMFILE: "open files",
    errno.ENFILE: "open files",
}


def _file_size_limited() -> bool:
    """Whether this process runs under a finite RLIMIT_FSIZE (ulimit -f)."""
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return soft != resource.RLIM_INFINITY


def _out_of_file_descriptors() -> bool:
    """Whether this process can open no more files right now (EMFILE/ENFILE)."""
    try:
        fd = os.open(os.devnull, os.O_RDONLY)
    except OSError as exc:
        return exc.errno in (errno.EMFILE, errno.ENFILE)
    os.close(fd)
    return False


def resource_problem(exc: BaseException) -> str | None:
    """The machine resource whose exhaustion caused ``exc`` (``"disk"``, ``"open files"``, …).

    Looks through SQLAlchemy's wrapper at the driver's error and its chain: an ``OSError``'s
    errno, SQLite's "database or disk is full" (or "unable to open database file" while this
    process is out of file descriptors), PostgreSQL's SQLSTATE class 53. None when ``exc`` is
    something else.
    """
    seen: set[int] = set()
    error: BaseException | None = exc
    while error is not None and id(error) not in seen:
        seen.add(id(error))
        if isinstance(error, ResourceExhausted):
            return error.resource
        if isinstance(error, OSError) and error.errno in _ERRNO_RESOURCES:
            return _ERRNO_RESOURCES[error.errno]
        if str(getattr(error, "sqlite_errorname", "")).startswith("SQLITE_IOERR") and (
            _file_size_limited()
        ):
            # SQLite reports a write refused with EFBIG as a plain I/O error
            return FILE_SIZE_LIMIT
        state = getattr(error, "sqlstate", None) or getattr(error, "pgcode", None)
        if isinstance(state, str) and state in _PG_RESOURCE_STATES:
            return _PG_RESOURCE_STATES[state]
        text = str(error).lower()
        if "database or disk is full" in text or "no space left on device" in text:
            return "disk"
        if "too many open files" in text or (
            "unable to open database file" in text and _out_of_file_descriptors()
        ):
            return "open files"
        nxt = getattr(error, "orig", None)
        error = nxt if isinstance(nxt, BaseException) else (error.__cause__ or error.__context__)
    return None


@contextlib.contextmanager
def write_tx(engine: Engine) -> Iterator[Connection]:
    """A write transaction, committed on exit (SQLite: ``BEGIN IMMEDIATE``).

    Raises :class:`CommitOutcomeUnknown` when the connection is lost during COMMIT.
    """
    with engine.connect().execution_options(write=True) as conn:
        tx = conn.begin()
        try:
            yield conn
        except BaseException as exc:
            with contextlib.suppress(Exception):
                tx.rollback()  # may fail too when the connection is gone; the first error wins
            dbapi_error = engine.dialect.loaded_dbapi.Error
            if isinstance(exc, dbapi_error):
                # A raw driver error (bulk inserts use the DBAPI cursor): the same typed
                # SQLAlchemy error as any other statement, so a lost server answers 503.
                raise sa.exc.DBAPIError.instance(
                    None, None, exc, dbapi_error, connection_invalidated=conn.invalidated
                ) from exc
            raise
        try:
            tx.commit()
        except sa.exc.DBAPIError as exc:
            resource = resource_problem(exc)
            if resource is not None and not exc.connection_invalidated:
                # the database answered COMMIT with the failure: rolled back, nothing stored
                raise ResourceExhausted(resource, str(exc.orig)) from exc
            if exc.connection_invalidated or isinstance(
                exc, sa.exc.OperationalError | sa.exc.InterfaceError
            ):
                raise CommitOutcomeUnknown(str(exc.orig)) from exc
            raise


@contextlib.contextmanager
def read_tx(engine: Engine) -> Iterator[Connection]:
    """A read transaction (consistent snapshot), rolled back on exit."""
    with engine.connect() as conn, conn.begin():
        yield conn
