"""auth_sessions: at most one open session per account, a partial unique index on each of
user_id and asset_id WHERE ended_at IS NULL (the one-session rule held by the database itself,
on SQLite as on PostgreSQL). Before the index, every open session of an account but its newest
is ended ("taken_over"), as the rule would have done; downgrade drops the indexes only.

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-07
"""

from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None

OPEN = sa.text("ended_at IS NULL")


def _end_all_but_the_newest(column: str) -> None:
    sessions = sa.table(
        "auth_sessions",
        sa.column("id", sa.Uuid()),
        sa.column(column, sa.Uuid()),
        sa.column("created_at"),
        sa.column("ended_at", sa.DateTime(timezone=True)),
        sa.column("end_reason"),
    )
    newer = sessions.alias("newer")
    a_newer_open_one = (
        sa.select(sa.literal(1))
        .where(
            newer.c[column] == sessions.c[column],
            newer.c.ended_at.is_(None),
            sa.or_(
                newer.c.created_at > sessions.c.created_at,
                sa.and_(newer.c.created_at == sessions.c.created_at, newer.c.id > sessions.c.id),
            ),
        )
        .exists()
    )
    now = datetime.now(UTC)
    if op.get_bind().dialect.name == "sqlite":  # SQLite keeps no zone: naive UTC, as UTCDateTime
        now = now.replace(tzinfo=None)
    op.execute(
        sessions.update()
        .where(sessions.c[column].is_not(None), sessions.c.ended_at.is_(None), a_newer_open_one)
        .values(ended_at=now, end_reason="taken_over")
    )


def upgrade() -> None:
    for column in ("user_id", "asset_id"):
        _end_all_but_the_newest(column)
    with op.batch_alter_table("auth_sessions") as batch_op:
        for column in ("user_id", "asset_id"):
            batch_op.create_index(
                f"ux_auth_sessions_{column}_open",
                [column],
                unique=True,
                postgresql_where=OPEN,
                sqlite_where=OPEN,
            )


def downgrade() -> None:
    with op.batch_alter_table("auth_sessions") as batch_op:
        for column in ("asset_id", "user_id"):
            batch_op.drop_index(f"ux_auth_sessions_{column}_open")
