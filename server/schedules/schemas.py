"""API shapes of schedules."""

from __future__ import annotations

import enum
import uuid

from pydantic import BaseModel, ConfigDict, Field

from server.kit.types import Name, Timestamp


class ScheduleKind(enum.StrEnum):
    """`once` at a time; `interval` every `interval_s` seconds; `cron` by a cron expression."""

    once = "once"
    interval = "interval"
    cron = "cron"


class MissedPolicy(enum.StrEnum):
    """What a schedule does about due times missed while the server was down: `skip` them, or
    `run_once` for all of them."""

    skip = "skip"
    run_once = "run_once"


class ScheduleCreate(BaseModel):
    """A schedule: `once` at `at`; `interval` every `interval_s` from `at` (default: now); `cron` in `timezone`."""

    model_config = ConfigDict(extra="forbid")
    name: Name
    mission_id: uuid.UUID
    uav_id: uuid.UUID
    base_id: uuid.UUID
    kind: ScheduleKind
    at: Timestamp | None = None
    interval_s: int | None = Field(
        default=None,
        ge=1,
        le=366 * 86400,
        description="seconds; at least the server's AEROBASE_SCHEDULE_MIN_INTERVAL_S (60 by default)",
    )
    cron: str | None = Field(default=None, max_length=120)
    timezone: str = Field(default="UTC", max_length=64)
    missed_policy: MissedPolicy = MissedPolicy.skip
    enabled: bool = True


class ScheduleUpdate(BaseModel):
    """Enable, disable, rename, or change the missed-run policy."""

    model_config = ConfigDict(extra="forbid")
    name: Name | None = None
    enabled: bool | None = None
    missed_policy: MissedPolicy | None = None


class ScheduleOut(BaseModel):
    """A schedule and its last firing."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    name: str
    mission_id: uuid.UUID
    uav_id: uuid.UUID
    base_id: uuid.UUID
    kind: ScheduleKind
    at: Timestamp | None
    interval_s: int | None
    cron: str | None
    timezone: str
    missed_policy: MissedPolicy
    enabled: bool
    next_due_at: Timestamp | None
    last_fired_at: Timestamp | None
    last_run_id: uuid.UUID | None
    last_result: str
    created_at: Timestamp
