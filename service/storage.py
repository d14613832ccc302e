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
import hashlib
import json
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

__all__ = [
    "SAMPLE_COLUMNS",
    "ApiKey",
    "Base",
    "Calibration",
    "CommitOutcomeUnknown",
    "Job",
    "RetrainLock",
    "Sample",
    "SampleArrays",
    "Spacecraft",
    "acquire_lock",
    "hash_key",
    "insert_samples",
    "make_engine",
    "normalise_url",
    "read_samples",
    "read_tx",
    "release_lock",
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


def make_engine(url: str, *, sqlite_synchronous: str = "FULL") -> Engine:
    """Engine with WAL, a busy timeout and foreign keys on SQLite; pre-ping on PostgreSQL."""
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
    conn.execute(
        sa.update(Spacecraft)
        .where(Spacecraft.pk == spacecraft_pk)
        .values(sample_count=Spacecraft.sample_count + inserted)
    )
    return inserted


@dataclass(frozen=True)
class SampleArrays:
    """Stored samples of one spacecraft, columnar, time-ordered."""

    t_utc_s: np.ndarray  # (N,) POSIX seconds of UTC
    columns: dict[str, np.ndarray]  # SAMPLE_COLUMNS -> (N,) float64, NaN where absent
    hk: dict[str, np.ndarray]  # hk_<name> -> (N,) float64, NaN where absent

    def __len__(self) -> int:
        return int(self.t_utc_s.shape[0])


def read_samples(
    conn: Connection,
    spacecraft_pk: int,
    *,
    start_utc_s: float | None = None,
    end_utc_s: float | None = None,
    limit: int | None = None,
) -> SampleArrays:
    """Time-ordered samples in ``[start, end]`` (an index range scan on the primary key)."""
    cols = ", ".join(("t_utc_us", *SAMPLE_COLUMNS, "hk"))
    sql = f"SELECT {cols} FROM samples WHERE spacecraft_pk = :pk"
    params: dict[str, Any] = {"pk": spacecraft_pk}
    if start_utc_s is not None:
        sql += " AND t_utc_us >= :start"
        params["start"] = round(start_utc_s * 1e6)
    if end_utc_s is not None:
        sql += " AND t_utc_us <= :end"
        params["end"] = round(end_utc_s * 1e6)
    sql += " ORDER BY t_utc_us"
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
