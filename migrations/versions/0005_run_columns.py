"""runs: step commands in their own table, flight times and landing error as columns

A run's current step commands (the JSON `step_commands` dict and the `pending_actions` key of
the JSON `facts`) become rows of `run_step_commands`; `facts`' `flight_started_at`,
`flight_ended_at` and `landing_error_m` become columns of `runs`, and `facts` goes. Existing
runs are carried over both ways.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23
"""

import json
import uuid
from datetime import UTC, datetime
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

# the tables as this revision sees them, for the data steps (never the models: they move on)
RUNS_BEFORE = sa.table(
    "runs",
    sa.column("id", sa.Uuid()),
    sa.column("step_commands", sa.JSON()),
    sa.column("facts", sa.JSON()),
)
RUNS_AFTER = sa.table(
    "runs",
    sa.column("id", sa.Uuid()),
    sa.column("flight_started_at", sa.DateTime(timezone=True)),
    sa.column("flight_ended_at", sa.DateTime(timezone=True)),
    sa.column("landing_error_m", sa.Float()),
)
STEP_COMMANDS = sa.table(
    "run_step_commands",
    sa.column("id", sa.Uuid()),
    sa.column("run_id", sa.Uuid()),
    sa.column("position", sa.Integer()),
    sa.column("target", sa.String()),
    sa.column("command", sa.String()),
    sa.column("command_id", sa.Uuid()),
)
COMMANDS = sa.table("commands", sa.column("id", sa.Uuid()))


def upgrade() -> None:
    op.create_table(
        "run_step_commands",
        sa.Column("run_id", sa.Uuid(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("target", sa.String(length=8), nullable=False),
        sa.Column("command", sa.String(length=64), nullable=False),
        sa.Column("command_id", sa.Uuid(), nullable=True),
        sa.Column("id", sa.Uuid(), nullable=False),
        sa.ForeignKeyConstraint(
            ["command_id"],
            ["commands.id"],
            name=op.f("fk_run_step_commands_command_id_commands"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["run_id"],
            ["runs.id"],
            name=op.f("fk_run_step_commands_run_id_runs"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_run_step_commands")),
    )
    with op.batch_alter_table("run_step_commands", schema=None) as batch_op:
        batch_op.create_index(
            "uq_run_step_commands_action", ["run_id", "target", "command"], unique=True
        )
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("flight_started_at", sa.DateTime(timezone=True), nullable=True)
        )
        batch_op.add_column(sa.Column("flight_ended_at", sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column("landing_error_m", sa.Float(), nullable=True))

    _carry_over()

    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("facts")
        batch_op.drop_column("step_commands")


def _carry_over() -> None:
    bind = op.get_bind()
    known = {row.id for row in bind.execute(sa.select(COMMANDS.c.id))}
    for run in bind.execute(sa.select(RUNS_BEFORE)).all():
        facts, issued = _obj(run.facts), _obj(run.step_commands)
        bind.execute(
            RUNS_AFTER.update()
            .where(RUNS_AFTER.c.id == run.id)
            .values(
                flight_started_at=_when(facts.get("flight_started_at")),
                flight_ended_at=_when(facts.get("flight_ended_at")),
                landing_error_m=_number(facts.get("landing_error_m")),
            )
        )
        rows: dict[tuple[str, str], uuid.UUID | None] = {}
        for action in facts.get("pending_actions") or []:
            if isinstance(action, str):  # "target:command", as a short-lived build wrote them
                target, _, name = action.partition(":")
                action = {"target": target, "command": name}
            if isinstance(action, dict) and action.get("target") and action.get("command"):
                rows.setdefault((str(action["target"]), str(action["command"])), None)
        for key, command_id in issued.items():
            target, _, name = str(key).partition(":")
            issued_id = uuid.UUID(str(command_id))
            if name and issued_id in known:  # a command gone with its asset was never observable
                rows[(target, name)] = issued_id
        for position, ((target, name), cid) in enumerate(rows.items()):
            bind.execute(
                STEP_COMMANDS.insert().values(
                    id=uuid.uuid4(), run_id=run.id, position=position,
                    target=target[:8], command=name[:64], command_id=cid,
                )
            )  # fmt: skip


def downgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("step_commands", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("facts", sa.JSON(), nullable=True))

    _carry_back()

    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.alter_column("step_commands", existing_type=sa.JSON(), nullable=False)
        batch_op.alter_column("facts", existing_type=sa.JSON(), nullable=False)
        batch_op.drop_column("landing_error_m")
        batch_op.drop_column("flight_ended_at")
        batch_op.drop_column("flight_started_at")
    with op.batch_alter_table("run_step_commands", schema=None) as batch_op:
        batch_op.drop_index("uq_run_step_commands_action")
    op.drop_table("run_step_commands")


def _carry_back() -> None:
    bind = op.get_bind()
    rows = bind.execute(sa.select(STEP_COMMANDS).order_by(STEP_COMMANDS.c.position)).all()
    for run in bind.execute(sa.select(RUNS_AFTER)).all():
        mine = [r for r in rows if r.run_id == run.id]
        facts: dict[str, Any] = {}
        for key, value in (
            ("flight_started_at", _iso(run.flight_started_at)),
            ("flight_ended_at", _iso(run.flight_ended_at)),
            ("landing_error_m", run.landing_error_m),
        ):
            if value is not None:
                facts[key] = value
        pending = [
            {"target": r.target, "command": r.command, "params": {}}
            for r in mine
            if r.command_id is None
        ]
        if pending:
            facts["pending_actions"] = pending
        issued = {f"{r.target}:{r.command}": str(r.command_id) for r in mine if r.command_id}
        bind.execute(
            RUNS_BEFORE.update()
            .where(RUNS_BEFORE.c.id == run.id)
            .values(facts=facts, step_commands=issued)
        )


def _obj(value: Any) -> dict[str, Any]:
    if isinstance(value, str):  # some drivers hand JSON back as text
        value = json.loads(value)
    return value if isinstance(value, dict) else {}


def _when(value: Any) -> datetime | None:
    if not isinstance(value, str):
        return None
    try:
        when = datetime.fromisoformat(value)
    except ValueError:
        return None
    when = when.replace(tzinfo=UTC) if when.tzinfo is None else when.astimezone(UTC)
    # SQLite keeps no zone: store naive UTC there, as the models' UTCDateTime does
    return when.replace(tzinfo=None) if op.get_bind().dialect.name == "sqlite" else when


def _iso(value: datetime | None) -> str | None:
    if value is None:
        return None
    return (
        value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
    ).isoformat()


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None
