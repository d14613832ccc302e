"""spacecraft.data_revision: a counter bumped whenever the spacecraft's stored samples change.

Answers computed from the samples (the diagnosis) are cached under this counter, so that any
change — an ingest that stored new rows, a delete, a quarantine or its release — makes the cached
answer stale at once, also when the number of samples comes back to what it was.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("spacecraft") as batch:
        batch.add_column(
            sa.Column("data_revision", sa.BigInteger, nullable=False, server_default="0")
        )


def downgrade() -> None:
    with op.batch_alter_table("spacecraft") as batch:
        batch.drop_column("data_revision")
