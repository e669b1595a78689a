"""All SQL of asset events read through the API."""

from __future__ import annotations

import uuid
from datetime import datetime

from server.kit.scope import ScopedRepository
from server.telemetry.models import AssetEvent


class EventRepository(ScopedRepository[AssetEvent]):
    """Events of the caller's organisation."""

    model = AssetEvent
    noun = "event"

    async def of_asset(
        self, asset_id: uuid.UUID, start: datetime, end: datetime, limit: int
    ) -> list[AssetEvent]:
        """Events of one asset in a time range, oldest first."""
        stmt = (
            self.select()
            .where(AssetEvent.asset_id == asset_id, AssetEvent.ts >= start, AssetEvent.ts < end)
            .order_by(AssetEvent.ts)
            .limit(limit)
        )
        return list((await self.db.execute(stmt)).scalars())
