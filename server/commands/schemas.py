"""API shapes of commands."""

from __future__ import annotations

import enum
import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from server.kit.types import Name, Timestamp


class CommandStatus(enum.StrEnum):
    """Where a command stands; `succeeded`, `rejected`, `failed`, `canceled` and `timed_out` are
    final (the wire vocabulary's `CommandStatus`, protocol/vocabulary.py)."""

    queued = "queued"
    sent = "sent"
    in_progress = "in_progress"
    succeeded = "succeeded"
    rejected = "rejected"
    failed = "failed"
    canceled = "canceled"
    timed_out = "timed_out"


class CommandCreate(BaseModel):
    """A command for an asset."""

    model_config = ConfigDict(extra="forbid")
    name: Name
    params: dict[str, Any] = Field(default_factory=dict, max_length=100)
    timeout_s: float = Field(default=60.0, gt=0, le=24 * 3600)


class StatusChangeOut(BaseModel):
    """One step of a command's history."""

    model_config = ConfigDict(from_attributes=True)
    at: Timestamp
    status: CommandStatus
    reason: str
    progress: dict[str, Any] | None


class CommandOut(BaseModel):
    """A command and, when asked for one, its history."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    asset_id: uuid.UUID
    name: str
    params: dict[str, Any]
    status: CommandStatus
    reason: str
    result: dict[str, Any] | None
    deadline: Timestamp
    created_at: Timestamp
    updated_at: Timestamp
    history: list[StatusChangeOut] = []
