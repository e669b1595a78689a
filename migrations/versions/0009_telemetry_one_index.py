"""telemetry: one unique index (asset, ts, seq) serves both the time-range reads and the replay
de-duplication; the two indexes it replaces cost a second B-tree insert per sample (issue 17:
SQLite 20-23 -> 10-13 us of CPU per row)

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-26
"""

from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("telemetry") as batch_op:
        batch_op.create_index("uq_telemetry_asset_ts_seq", ["asset_id", "ts", "seq"], unique=True)
        batch_op.drop_index("uq_telemetry_asset_seq_ts")
        batch_op.drop_index("ix_telemetry_asset_ts")


def downgrade() -> None:
    with op.batch_alter_table("telemetry") as batch_op:
        batch_op.create_index("ix_telemetry_asset_ts", ["asset_id", "ts"], unique=False)
        batch_op.create_index("uq_telemetry_asset_seq_ts", ["asset_id", "seq", "ts"], unique=True)
        batch_op.drop_index("uq_telemetry_asset_ts_seq")
