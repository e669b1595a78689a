"""API shapes of the audit log."""

from __future__ import annotations

import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict

from server.kit.types import Timestamp


class AuditEventOut(BaseModel):
    """One audit event."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    at: Timestamp
    actor_kind: str
    actor_id: str | None
    action: str
    target: str | None
    client_addr: str | None
    details: dict[str, Any]
