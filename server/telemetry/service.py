"""Telemetry decisions: what an asset's durable stream writes besides samples (its events, how far
the stream is stored) and what the API reads back.

The ingest calls the functions inside its batch's transaction; they add and flush, the ingest
commits. The API reads through TelemetryService.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy.ext.asyncio import AsyncSession

from server.assets.repository import AssetRepository
from server.kit.errors import NotFound, Unprocessable
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.telemetry import repository
from server.telemetry.models import AssetEvent, AssetStream
from server.telemetry.repository import EventRepository
from server.telemetry.store import Aggregate, Query, TelemetryStore


class StreamOfAnotherAsset(ValueError):
    """A hello named a stream that belongs to another asset."""


def _text(value: Any) -> str:
    # valid JSON, but PostgreSQL's text types cannot hold NUL: stored without it on every database
    return str(value).replace("\x00", "")


def record_event(
    db: AsyncSession,
    organization_id: uuid.UUID,
    asset_id: uuid.UUID,
    ts: datetime,
    payload: Mapping[str, Any],
) -> None:
    """Add one event an asset reported (name and message cut to their column sizes, without NUL)."""
    db.add(
        AssetEvent(
            organization_id=organization_id,
            asset_id=asset_id,
            ts=ts,
            name=_text(payload.get("name", ""))[:200],
            severity=_text(payload.get("severity", "info"))[:16],
            message=_text(payload.get("message", ""))[:2000],
            data=payload.get("data") or {},
        )
    )


async def stream_position(db: AsyncSession, stream_id: uuid.UUID, asset_id: uuid.UUID) -> int:
    """The highest stored seq of a stream, registering a new stream at 0.

    Raises StreamOfAnotherAsset when the stream is known under another asset.
    """
    row = await db.get(AssetStream, stream_id)
    if row is None:
        db.add(AssetStream(stream_id=stream_id, asset_id=asset_id, last_seq=0))
        await db.flush()
        return 0
    if row.asset_id != asset_id:
        raise StreamOfAnotherAsset("stream belongs to another asset")
    return int(row.last_seq)


async def advance_streams(db: AsyncSession, highest: Mapping[uuid.UUID, int]) -> None:
    """Move each stream's stored position up to `highest[stream]` (never down: replays are harmless)."""
    for row in await repository.streams(db, highest):
        row.last_seq = max(row.last_seq, highest[row.stream_id])


def time_range(start: datetime | None, end: datetime | None) -> tuple[datetime, datetime]:
    """[start, end) of a read: by default the hour before `end` (default now)."""
    end = end or utcnow()
    try:
        start = start or end - timedelta(hours=1)
    except OverflowError as err:
        raise Unprocessable("end is too early for the default one-hour window; give start") from err
    if start.tzinfo is None or end.tzinfo is None:
        raise Unprocessable("start and end need a time zone (e.g. 2026-11-22T10:00:00Z)")
    if start >= end:
        raise Unprocessable("start must be before end")
    return start, end


class TelemetryService(Service):
    """Samples and events of the caller's organisation's assets."""

    def __init__(self, uow: UnitOfWork, principal: Principal, store: TelemetryStore) -> None:
        super().__init__(uow, principal)
        self.store = store
        self.assets = AssetRepository(self.db, principal)

    async def samples(
        self,
        asset_id: uuid.UUID,
        start: datetime | None,
        end: datetime | None,
        fields: list[str] | None,
        every: float | None,
        agg: Aggregate,
        limit: int,
    ) -> list[dict[str, Any]]:
        """Samples of an asset of the caller's organisation (NotFound otherwise) in [start, end):
        raw, or downsampled to `every`-second buckets."""
        await self.assets.get(asset_id)
        start, end = time_range(start, end)
        return await self.store.query(Query(asset_id, start, end, fields, every, agg, limit))

    async def latest(self, asset_id: uuid.UUID) -> dict[str, Any]:
        """The newest sample of an asset; NotFound before its first."""
        await self.assets.get(asset_id)
        row = await self.store.latest(asset_id)
        if row is None:
            raise NotFound(f"asset {asset_id} has sent no telemetry yet")
        return row

    async def events(
        self, asset_id: uuid.UUID, start: datetime | None, end: datetime | None, page: Page
    ) -> Paged[AssetEvent]:
        """Events of an asset in [start, end)."""
        await self.assets.get(asset_id)
        start, end = time_range(start, end)
        return await EventRepository(self.db, self.principal).of_asset(asset_id, start, end, page)
