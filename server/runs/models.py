"""Tables of runs, the commands of their current step, and their transitions."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, Index, String
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.time import utcnow


class Run(IdMixin, Base):
    """One autonomous run: a mission flown by a UAV from a landing base and back."""

    __tablename__ = "runs"
    __table_args__ = (
        Index("ix_runs_org_created", "organization_id", "created_at"),
        Index("ix_runs_state_lease", "state", "lease_until"),
        # one run per due time of a schedule, whatever the number of server processes
        Index("uq_runs_schedule_due", "schedule_id", "scheduled_for", unique=True),
    )

    organization_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE")
    )
    mission_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("missions.id", ondelete="RESTRICT"))
    uav_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("assets.id", ondelete="RESTRICT"))
    base_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("assets.id", ondelete="RESTRICT"))
    schedule_id: Mapped[uuid.UUID | None] = mapped_column(default=None)
    scheduled_for: Mapped[datetime | None] = mapped_column(default=None)
    state: Mapped[str] = mapped_column(String(16), default="pending")
    step_started_at: Mapped[datetime] = mapped_column(default=utcnow)
    # the current step's commands are out (its RunStepCommand rows all have a command_id)
    actions_issued: Mapped[bool] = mapped_column(default=False)
    aborting: Mapped[bool] = mapped_column(default=False)
    abort_requested: Mapped[bool] = mapped_column(default=False)
    abort_reason: Mapped[str] = mapped_column(String(2000), default="")
    # completed | completed_with_issues | incomplete | aborted | failed (runs/outcome.py)
    outcome: Mapped[str | None] = mapped_column(String(32), default=None)
    cause: Mapped[str | None] = mapped_column(String(64), default=None)
    # degradations that did not stop the job: charging_refused, landing_off_contacts,
    # landed_without_precision
    issues: Mapped[list[Any]] = mapped_column(JSON, default=list)
    reason: Mapped[str] = mapped_column(String(2000), default="")
    alert: Mapped[bool] = mapped_column(default=False)
    flight_started_at: Mapped[datetime | None] = mapped_column(default=None)
    flight_ended_at: Mapped[datetime | None] = mapped_column(default=None)
    landing_error_m: Mapped[float | None] = mapped_column(Float, default=None)
    # take-off to touchdown by the UAV's own events, written when the run ends
    flight_time_s: Mapped[float | None] = mapped_column(Float, default=None)
    lease_owner: Mapped[str | None] = mapped_column(String(64), default=None)
    lease_until: Mapped[datetime] = mapped_column(default=utcnow)
    created_by: Mapped[str | None] = mapped_column(String(64), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(default=None)


class RunStepCommand(IdMixin, Base):
    """One command of a run's current step: pending until issued, then the command it became.

    A transition replaces a run's rows with the exit's safe actions and the new step's own; the
    engine issues the pending ones (`command_id` null) in `position` order.
    """

    __tablename__ = "run_step_commands"
    __table_args__ = (
        Index("uq_run_step_commands_action", "run_id", "target", "command", unique=True),
    )

    run_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"))
    position: Mapped[int] = mapped_column(default=0)
    target: Mapped[str] = mapped_column(String(8))  # base | uav
    command: Mapped[str] = mapped_column(String(64))  # its name in protocol.vocabulary
    command_id: Mapped[uuid.UUID | None] = mapped_column(
        ForeignKey("commands.id", ondelete="CASCADE"), default=None
    )


class RunTransition(IdMixin, Base):
    """One step of a run's timeline, written before the step is acted on."""

    __tablename__ = "run_transitions"

    run_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    at: Mapped[datetime] = mapped_column(default=utcnow)
    from_state: Mapped[str] = mapped_column(String(16))
    to_state: Mapped[str] = mapped_column(String(16))
    reason: Mapped[str] = mapped_column(String(2000), default="")
    cause: Mapped[str] = mapped_column(String(64), default="")
