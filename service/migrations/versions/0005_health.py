"""Calibration health: one row per scored batch of new samples (issue 47).

Each accepted upload's new samples are scored against the calibration in service
(:mod:`service.health`): the batch's RMS, its noise floor, the change rule's CUSUM, and — on the
point that raised the alarm — when the change began. ``stale`` marks the points of a version
after its alarm.

Revision ID: 0005_health
Revises: 0004
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005_health"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "health_points",
        sa.Column("pk", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column(
            "spacecraft_pk",
            sa.Integer,
            sa.ForeignKey("spacecraft.pk", ondelete="CASCADE"),
            nullable=False,
        ),
        sa.Column("version", sa.Integer, nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("start_us", sa.BigInteger, nullable=False),
        sa.Column("end_us", sa.BigInteger, nullable=False),
        sa.Column("n", sa.BigInteger, nullable=False),
        sa.Column("rms_nt", sa.Float, nullable=False),
        sa.Column("noise_nt", sa.Float, nullable=True),
        sa.Column("ref_rms_nt", sa.Float, nullable=False),
        sa.Column("cusum", sa.Float, nullable=False),
        sa.Column("stale", sa.Boolean, nullable=False),
        sa.Column("change_at_us", sa.BigInteger, nullable=True),
        sa.Column("created_at", sa.Float, nullable=False),
        sa.UniqueConstraint("spacecraft_pk", "start_us", "version", "kind"),
    )
    op.create_index("ix_health_points_sc_end", "health_points", ["spacecraft_pk", "end_us"])


def downgrade() -> None:
    op.drop_table("health_points")
