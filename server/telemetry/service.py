"""What an asset's durable stream writes besides samples: its events and how far the stream is stored.

The ingest calls these inside its batch's transaction; they add and flush, the ingest commits.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy.ext.asyncio import AsyncSession

from server.telemetry import repository
from server.telemetry.models import AssetEvent, AssetStream


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
