"""API shapes of the audit log."""

from __future__ import annotations

import enum
import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict

from server.kit.types import Timestamp


class ActorKind(enum.StrEnum):
    """Who did it: a user, an asset, the server itself, or the `aerobase admin` command line."""

    user = "user"
    asset = "asset"
    system = "system"
    cli = "cli"


class AuditEventOut(BaseModel):
    """One audit event."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    at: Timestamp
    actor_kind: ActorKind
    actor_id: str | None
    action: str
    target: str | None
    client_addr: str | None
    details: dict[str, Any]
