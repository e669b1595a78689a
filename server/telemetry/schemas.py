"""API shapes of telemetry and events."""

from __future__ import annotations

import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict

from server.kit.types import Timestamp


class EventOut(BaseModel):
    """An asset event."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    asset_id: uuid.UUID
    ts: Timestamp
    name: str
    severity: str
    message: str
    data: dict[str, Any]
