"""memberships: disabling a user is per organisation (`memberships.is_active`)

An admin of one organisation disabled the whole account (`users.is_active`), locking the user
out of every other organisation too. The flag moves to the membership: a user disabled before
this revision keeps every membership disabled and the account itself becomes active again.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-24
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

USERS = sa.table("users", sa.column("id", sa.Uuid()), sa.column("is_active", sa.Boolean()))
MEMBERSHIPS = sa.table(
    "memberships",
    sa.column("user_id", sa.Uuid()),
    sa.column("is_active", sa.Boolean()),
)


def upgrade() -> None:
    with op.batch_alter_table("memberships") as batch:
        batch.add_column(
            sa.Column("is_active", sa.Boolean(), nullable=False, server_default=sa.true())
        )
    disabled = sa.select(USERS.c.id).where(USERS.c.is_active.is_(False))
    op.execute(
        MEMBERSHIPS.update().where(MEMBERSHIPS.c.user_id.in_(disabled)).values(is_active=False)
    )
    op.execute(USERS.update().where(USERS.c.is_active.is_(False)).values(is_active=True))


def downgrade() -> None:
    off = sa.select(MEMBERSHIPS.c.user_id).where(MEMBERSHIPS.c.is_active.is_(False))
    op.execute(USERS.update().where(USERS.c.id.in_(off)).values(is_active=False))
    with op.batch_alter_table("memberships") as batch:
        batch.drop_column("is_active")
