"""API shapes of telemetry and events."""

from __future__ import annotations

import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict, RootModel

from server.kit.types import Timestamp


class TelemetrySample(RootModel[dict[str, Any]]):
    """One sample: `ts` (when the asset measured it) and the asset's fields by dotted name, e.g.
    {"ts": "2026-11-22T10:00:00Z", "gnss.fix": "rtk_fixed", "battery.pct": 87.5}."""


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
