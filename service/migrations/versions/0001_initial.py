"""Initial schema: spacecraft, samples, calibrations, jobs, retrain_locks, api_keys.

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

_OPTIONAL = (
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


def upgrade() -> None:
    op.create_table(
        "spacecraft",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("id", sa.String(64), nullable=False, unique=True),
        sa.Column("tle", sa.Text, nullable=True),
        sa.Column("omm", sa.JSON, nullable=True),
        sa.Column("attitude_frame", sa.String(8), nullable=False),
        sa.Column("schedule", sa.JSON, nullable=True),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.Column("sample_count", sa.BigInteger, nullable=False),
        sa.Column("samples_at_last_job", sa.BigInteger, nullable=False),
        sa.Column("last_job_at", sa.Float, nullable=True),
    )
    op.create_table(
        "samples",
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            primary_key=True,
        ),
        sa.Column("t_utc_us", sa.BigInteger, primary_key=True),
        *[sa.Column(c, sa.Float, nullable=False) for c in ("b_x", "b_y", "b_z")],
        *[sa.Column(c, sa.Float, nullable=True) for c in _OPTIONAL],
        sa.Column("hk", sa.Text, nullable=True),
        sqlite_with_rowid=False,
    )
    op.create_table(
        "calibrations",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("version", sa.Integer, nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("reason", sa.Text, nullable=True),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.Column("job_id", sa.String(32), nullable=True),
        sa.Column("holdout_rms_nt", sa.Float, nullable=True),
        sa.Column("document", sa.JSON, nullable=False),
        sa.Column("provenance", sa.JSON, nullable=False),
        sa.UniqueConstraint("spacecraft_pk", "version"),
    )
    op.create_table(
        "jobs",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("trigger", sa.String(16), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("error", sa.Text, nullable=True),
        sa.Column("params", sa.JSON, nullable=False),
        sa.Column("result", sa.JSON, nullable=True),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.Column("started_at", sa.Float, nullable=True),
        sa.Column("finished_at", sa.Float, nullable=True),
    )
    op.create_index("ix_jobs_spacecraft_pk", "jobs", ["spacecraft_pk"])
    op.create_table(
        "retrain_locks",
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            primary_key=True,
        ),
        sa.Column("job_id", sa.String(32), nullable=False),
        sa.Column("acquired_at", sa.Float, nullable=False),
    )
    op.create_table(
        "api_keys",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("key_hash", sa.String(64), nullable=False, unique=True),
        sa.Column("prefix", sa.String(12), nullable=False),
        sa.Column("name", sa.String(128), nullable=False),
        sa.Column("scopes", sa.JSON, nullable=False),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.Column("revoked", sa.Boolean, nullable=False),
    )


def downgrade() -> None:
    for table in ("api_keys", "retrain_locks", "jobs", "calibrations", "samples", "spacecraft"):
        op.drop_table(table)
