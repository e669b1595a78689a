"""HTTP routes of airspace zones: CRUD and import from a GeoJSON FeatureCollection."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.airspace.models import AirspaceZone
from server.airspace.schemas import FeatureCollectionIn, ZoneIn, ZoneOut, ZoneUpdate
from server.airspace.service import AirspaceService
from server.airspace.zones import is_active
from server.deps import Operator, UoW, Viewer
from server.kit.paging import PAGED, Paging
from server.kit.time import utcnow

router = APIRouter(tags=["airspace"])


def _service(uow: UoW, principal: Viewer) -> AirspaceService:
    return AirspaceService(uow, principal)


def _operator_service(uow: UoW, principal: Operator) -> AirspaceService:
    return AirspaceService(uow, principal)


Zones = Annotated[AirspaceService, Depends(_service)]
ZonesOperator = Annotated[AirspaceService, Depends(_operator_service)]


def _out(zone: AirspaceZone) -> ZoneOut:
    return ZoneOut.model_validate(
        {
            "id": zone.id,
            "organization_id": zone.organization_id,
            "base_id": zone.base_id,
            "name": zone.name,
            "description": zone.description,
            "kind": zone.kind,
            "geometry": zone.geometry,
            "radius_m": zone.radius_m,
            "floor_m": zone.floor_m,
            "ceiling_m": zone.ceiling_m,
            "altitude_ref": zone.altitude_ref,
            "windows": zone.windows,
            "active": is_active(zone, utcnow()),
            "created_at": zone.created_at,
            "updated_at": zone.updated_at,
        }
    )


@router.get("/api/v1/airspace/zones", response_model=list[ZoneOut], responses=PAGED)
async def list_zones(
    zones: Zones, pages: Paging, base_id: uuid.UUID | None = None
) -> list[ZoneOut]:
    """Zones of the caller's organisation, oldest first; `base_id`: those applying there."""
    found = await zones.list_zones(pages.page, base_id)
    pages.respond(found.total)
    return [_out(z) for z in found.items]


@router.post("/api/v1/airspace/zones", status_code=201, response_model=ZoneOut)
async def create_zone(body: ZoneIn, zones: ZonesOperator) -> ZoneOut:
    """Create a zone (operators); 422 lists every problem."""
    return _out(await zones.create(body))


@router.post("/api/v1/airspace/zones/import", status_code=201, response_model=list[ZoneOut])
async def import_zones(body: FeatureCollectionIn, zones: ZonesOperator) -> list[ZoneOut]:
    """Create a zone from each Feature of a GeoJSON FeatureCollection, all or none (operators);
    422 names every feature refused and why."""
    return [_out(z) for z in await zones.import_collection(body)]


@router.get("/api/v1/airspace/zones/{zone_id}", response_model=ZoneOut)
async def get_zone(zone_id: uuid.UUID, zones: Zones) -> ZoneOut:
    """One zone of the caller's organisation."""
    return _out(await zones.get(zone_id))


@router.patch("/api/v1/airspace/zones/{zone_id}", response_model=ZoneOut)
async def update_zone(zone_id: uuid.UUID, body: ZoneUpdate, zones: ZonesOperator) -> ZoneOut:
    """Change a zone (operators); the result is validated as a whole."""
    changes = body.model_dump(mode="json", exclude_unset=True)
    return _out(await zones.update(zone_id, changes))


@router.delete("/api/v1/airspace/zones/{zone_id}", status_code=204, response_class=Response)
async def delete_zone(zone_id: uuid.UUID, zones: ZonesOperator) -> Response:
    """Delete a zone (operators)."""
    await zones.delete(zone_id)
    return Response(status_code=204)
