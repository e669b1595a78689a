"""API shapes of telemetry and events."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from pydantic import BaseModel, ConfigDict


class EventOut(BaseModel):
    """An asset event."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    asset_id: uuid.UUID
    ts: datetime
    name: str
    severity: str
    message: str
    data: dict[str, Any]
