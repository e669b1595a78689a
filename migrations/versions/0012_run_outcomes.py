"""run_outcomes: a run's outcome says whether its job was done (completed, completed_with_issues,
incomplete, aborted, failed: server/runs/outcome.py), with the degradations that did not stop it
(`issues`) and the flight time the UAV reported (`flight_time_s`). Runs already recorded are
re-judged where their timeline tells: a completed run turned home by the battery reserve, the
geofence or its time budget is `incomplete`; one whose charging failed is `completed_with_issues`.

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-07
"""

import sqlalchemy as sa
from alembic import op

revision = "0012"
down_revision = "0011"
branch_labels = None
depends_on = None

EARLY = "('battery_reserve', 'fence_breach', 'mission_overrun')"
FLYING_EXIT = (
    "SELECT t.cause FROM run_transitions t WHERE t.run_id = runs.id AND t.from_state = 'flying' "
    "AND t.to_state = 'landing' ORDER BY t.at LIMIT 1"
)


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch_op:
        batch_op.alter_column(
            "outcome", existing_type=sa.String(length=16), type_=sa.String(length=32)
        )
        batch_op.add_column(sa.Column("issues", sa.JSON(), nullable=False, server_default="[]"))
        batch_op.add_column(sa.Column("flight_time_s", sa.Float(), nullable=True))
    op.execute(
        "UPDATE runs SET outcome = 'completed_with_issues', cause = 'charging_refused', "
        """issues = '["charging_refused"]' WHERE outcome = 'completed' """
        "AND cause = 'charging_failed'"
    )
    op.execute(
        f"UPDATE runs SET state = 'incomplete', outcome = 'incomplete', cause = ({FLYING_EXIT}) "
        f"WHERE state = 'completed' AND ({FLYING_EXIT}) IN {EARLY}"
    )


def downgrade() -> None:
    op.execute(
        "UPDATE runs SET state = 'completed', outcome = 'completed' WHERE state = 'incomplete'"
    )
    op.execute(
        "UPDATE runs SET outcome = 'completed', cause = 'charging_failed' "
        "WHERE outcome = 'completed_with_issues'"
    )
    with op.batch_alter_table("runs") as batch_op:
        batch_op.drop_column("flight_time_s")
        batch_op.drop_column("issues")
        batch_op.alter_column(
            "outcome", existing_type=sa.String(length=32), type_=sa.String(length=16)
        )
