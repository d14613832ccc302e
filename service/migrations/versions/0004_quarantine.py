"""Quarantines and the data audit log.

Quarantined samples stay stored but are left out of retraining and diagnosis until released;
``data_audit`` records every quarantine, release and deletion (who, when, range, count). Each of
them bumps ``spacecraft.data_revision`` (revision 0002): caches keyed on the samples go stale.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "quarantines",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("start_us", sa.BigInteger, nullable=False),
        sa.Column("end_us", sa.BigInteger, nullable=False),
        sa.Column("reason", sa.Text, nullable=False),
        sa.Column("created_by", sa.String(128), nullable=False),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.Column("n_samples", sa.BigInteger, nullable=False),
        sa.Column("released_at", sa.Float, nullable=True),
        sa.Column("released_by", sa.String(128), nullable=True),
    )
    op.create_index("ix_quarantines_spacecraft_pk", "quarantines", ["spacecraft_pk"])
    op.create_table(
        "data_audit",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("action", sa.String(16), nullable=False),
        sa.Column("start_us", sa.BigInteger, nullable=False),
        sa.Column("end_us", sa.BigInteger, nullable=False),
        sa.Column("n_samples", sa.BigInteger, nullable=False),
        sa.Column("who", sa.String(128), nullable=False),
        sa.Column("at", sa.Float, nullable=False),
        sa.Column("quarantine_pk", sa.Integer, nullable=True),
        sa.Column("reason", sa.Text, nullable=True),
    )
    op.create_index("ix_data_audit_spacecraft_pk", "data_audit", ["spacecraft_pk"])


def downgrade() -> None:
    op.drop_table("data_audit")
    op.drop_table("quarantines")
