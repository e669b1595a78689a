"""All SQL of asset events and stream positions."""

from __future__ import annotations

import uuid
from collections.abc import Iterable, Mapping
from datetime import datetime

from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository
from server.telemetry import bulk
from server.telemetry.models import AssetEvent, AssetStream


class EventRepository(ScopedRepository[AssetEvent]):
    """Events of the caller's organisation."""

    model = AssetEvent
    noun = "event"

    async def of_asset(
        self, asset_id: uuid.UUID, start: datetime, end: datetime, page: Page
    ) -> Paged[AssetEvent]:
        """Events of one asset in a time range, oldest first."""
        stmt = (
            self.select()
            .where(AssetEvent.asset_id == asset_id, AssetEvent.ts >= start, AssetEvent.ts < end)
            .order_by(AssetEvent.ts, AssetEvent.created_at, AssetEvent.id)  # ties: as received
        )
        return await paginate(self.db, stmt, page)


async def advance_streams(db: AsyncSession, highest: Mapping[uuid.UUID, int]) -> None:
    """Raise each stream's last_seq to `highest[stream]` where it is lower (portable `GREATEST`:
    one driver-level statement, `bulk.py`; no rows loaded)."""
    # unscoped: streams of connected, authenticated assets (the socket proved whose they are)
    await bulk.writer(db).advance_streams(db, highest)


async def streams(db: AsyncSession, stream_ids: Iterable[uuid.UUID]) -> list[AssetStream]:
    """The rows of these streams (unscoped: streams of connected, authenticated assets)."""
    # unscoped: streams of connected, authenticated assets (the socket proved whose they are)
    stmt = select(AssetStream).where(AssetStream.stream_id.in_(list(stream_ids)))
    return list((await db.execute(stmt)).scalars())
