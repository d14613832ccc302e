"""Ingest log: one row per telemetry upload (accepted, duplicate and rejected row counts).

The dashboard plots the rejected rows per day from it (service/routes/dashboard.py).

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "ingest_log",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("received_at", sa.Float, nullable=False),
        sa.Column("fmt", sa.String(16), nullable=False),
        sa.Column("accepted", sa.BigInteger, nullable=False),
        sa.Column("duplicates", sa.BigInteger, nullable=False),
        sa.Column("rejected", sa.BigInteger, nullable=False),
        sa.Column("examples", sa.JSON, nullable=True),
    )
    op.create_index("ix_ingest_log_spacecraft_pk", "ingest_log", ["spacecraft_pk"])


def downgrade() -> None:
    op.drop_table("ingest_log")
