"""HTTP routes of telemetry and events."""

from __future__ import annotations

import uuid
from datetime import datetime, timedelta
from typing import Any, Literal

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict

from server.assets.repository import AssetRepository
from server.deps import DB, ServicesDep, Viewer
from server.kit.errors import NotFound, Unprocessable
from server.kit.time import utcnow
from server.telemetry.repository import EventRepository
from server.telemetry.store import Query as StoreQuery

router = APIRouter(tags=["telemetry"])


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


def _range(start: datetime | None, end: datetime | None) -> tuple[datetime, datetime]:
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


@router.get("/api/v1/assets/{asset_id}/telemetry")
async def telemetry(
    asset_id: uuid.UUID,
    principal: Viewer,
    services: ServicesDep,
    db: DB,
    start: datetime | None = None,
    end: datetime | None = None,
    fields: str | None = Query(None, max_length=2000, description="comma-separated dotted names"),
    every: float | None = Query(None, gt=0, le=86400, description="bucket seconds"),
    agg: Literal["mean", "last"] = "mean",
    limit: int = Query(10_000, ge=1, le=100_000),
) -> list[dict[str, Any]]:
    """Samples of an asset in [start, end): raw, or downsampled to `every`-second buckets."""
    await AssetRepository(db, principal).get(asset_id)
    start, end = _range(start, end)
    wanted = [f.strip() for f in fields.split(",") if f.strip()] if fields else None
    return await services.telemetry.query(
        StoreQuery(asset_id, start, end, wanted, every, agg, limit)
    )  # type: ignore[no-any-return]


@router.get("/api/v1/assets/{asset_id}/telemetry/latest")
async def telemetry_latest(
    asset_id: uuid.UUID, principal: Viewer, services: ServicesDep, db: DB
) -> dict[str, Any]:
    """The newest sample of an asset."""
    await AssetRepository(db, principal).get(asset_id)
    row = await services.telemetry.latest(asset_id)
    if row is None:
        raise NotFound(f"asset {asset_id} has sent no telemetry yet")
    return row  # type: ignore[no-any-return]


@router.get("/api/v1/assets/{asset_id}/events", response_model=list[EventOut])
async def events(
    asset_id: uuid.UUID,
    principal: Viewer,
    db: DB,
    start: datetime | None = None,
    end: datetime | None = None,
    limit: int = Query(1000, ge=1, le=10_000),
) -> list[EventOut]:
    """Events of an asset in [start, end)."""
    await AssetRepository(db, principal).get(asset_id)
    start, end = _range(start, end)
    return [
        EventOut.model_validate(e)
        for e in await EventRepository(db, principal).of_asset(asset_id, start, end, limit)
    ]
