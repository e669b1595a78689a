"""login_known_clients: the addresses from which each account last logged in, so that wrong
passwords from elsewhere count apart from that address's and cannot lock the account out

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-27
"""

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "login_known_clients",
        sa.Column("account_key", sa.String(length=320), nullable=False),
        sa.Column("addr", sa.String(length=64), nullable=False),
        sa.Column("last_success_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("account_key", "addr", name=op.f("pk_login_known_clients")),
    )
    with op.batch_alter_table("login_known_clients") as batch_op:
        batch_op.create_index(
            batch_op.f("ix_login_known_clients_last_success_at"), ["last_success_at"]
        )


def downgrade() -> None:
    with op.batch_alter_table("login_known_clients") as batch_op:
        batch_op.drop_index(batch_op.f("ix_login_known_clients_last_success_at"))
    op.drop_table("login_known_clients")
