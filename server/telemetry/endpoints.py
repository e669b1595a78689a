"""HTTP routes of telemetry and events."""

from __future__ import annotations

import uuid
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query

from server.deps import ServicesDep, UoW, Viewer
from server.kit.paging import PAGED, Pager, pager
from server.kit.types import Timestamp
from server.telemetry.schemas import EventOut, TelemetrySample
from server.telemetry.service import TelemetryService

router = APIRouter(tags=["telemetry"])


def _service(uow: UoW, principal: Viewer, services: ServicesDep) -> TelemetryService:
    return TelemetryService(uow, principal, services.telemetry)


Telemetry = Annotated[TelemetryService, Depends(_service)]


@router.get(
    "/api/v1/assets/{asset_id}/telemetry",
    response_model=list[TelemetrySample],
    operation_id="listTelemetry",
)
async def telemetry(
    asset_id: uuid.UUID,
    samples: Telemetry,
    start: Timestamp | None = None,
    end: Timestamp | None = None,
    fields: str | None = Query(None, max_length=2000, description="comma-separated dotted names"),
    every: float | None = Query(
        None, ge=0.001, le=86400, description="bucket seconds (a millisecond to a day)"
    ),
    agg: Literal["mean", "last"] = "mean",
    limit: int = Query(10_000, ge=1, le=100_000),
) -> list[dict[str, Any]]:
    """Samples of an asset in [start, end): raw, or downsampled to `every`-second buckets."""
    wanted = [f.strip() for f in fields.split(",") if f.strip()] if fields else None
    return await samples.samples(asset_id, start, end, wanted, every, agg, limit)


@router.get(
    "/api/v1/assets/{asset_id}/telemetry/latest",
    response_model=TelemetrySample,
    operation_id="getLatestTelemetry",
)
async def telemetry_latest(asset_id: uuid.UUID, samples: Telemetry) -> dict[str, Any]:
    """The newest sample of an asset."""
    return await samples.latest(asset_id)


@router.get(
    "/api/v1/assets/{asset_id}/events",
    response_model=list[EventOut],
    responses=PAGED,
    operation_id="listEvents",
)
async def events(
    asset_id: uuid.UUID,
    samples: Telemetry,
    pages: Annotated[Pager, Depends(pager(default=1000, maximum=10_000))],
    start: Timestamp | None = None,
    end: Timestamp | None = None,
) -> list[EventOut]:
    """Events of an asset in [start, end), oldest first (one `ts`: in the order received)."""
    found = await samples.events(asset_id, start, end, pages.page)
    pages.respond(found.total)
    return [EventOut.model_validate(e) for e in found.items]
