"""missions, schedules, memberships, assets: a version counter for ETag / If-Match

The resources operators edit carry `version` (1 for every existing row), raised by every UPDATE
and checked in its WHERE clause (server/kit/etag.py), so concurrent edits are detected (412).

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-25
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None

TABLES = ("missions", "schedules", "memberships", "assets")


def upgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table) as batch:
            batch.add_column(
                sa.Column("version", sa.Integer(), nullable=False, server_default=sa.text("1"))
            )


def downgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table) as batch:
            batch.drop_column("version")
