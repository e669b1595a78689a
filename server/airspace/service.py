"""Decisions about airspace zones: create, import, change, and which apply to a flight."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from pydantic import ValidationError

from server.airspace.check import AirspaceProblem, ZoneShape
from server.airspace.fence import Fence, build_fence
from server.airspace.models import AirspaceZone
from server.airspace.plan import check_flight, plan_fence_zones
from server.airspace.repository import ZoneRepository
from server.airspace.schemas import FeatureCollectionIn, ZoneIn
from server.airspace.zones import (
    is_active,
    pydantic_problems,
    shape_of,
    with_defaults,
    zone_problems,
)
from server.assets.models import AssetKind
from server.assets.repository import AssetRepository
from server.audit.service import record
from server.kit.errors import NotFound, Unprocessable
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.missions.validate import Home, Problem


def rejected(problems: list[Problem], code: str = "invalid_zone") -> Unprocessable:
    """The 422 listing every problem of the zones given."""
    first = problems[0]
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return Unprocessable(
        f"{first.where}: {first.what}{more}", code=code, details=[p.as_dict() for p in problems]
    )


class AirspaceService(Service):
    """Zones of the caller's organisation."""

    def __init__(self, uow: UnitOfWork, principal: Principal) -> None:
        super().__init__(uow, principal)
        self.repo = ZoneRepository(self.db, principal)

    async def _base_problems(self, zone: ZoneIn, where: str) -> list[Problem]:
        if zone.base_id is None:
            return []
        at = f"{where}.properties.base_id" if where else "base_id"
        try:
            base = await AssetRepository(self.db, self.principal).get(zone.base_id)
        except NotFound:
            return [Problem(at, "no such base in this organisation", str(zone.base_id))]
        if base.kind != AssetKind.landing_base:
            return [Problem(at, "the asset is not a landing base", str(zone.base_id))]
        return []

    def _row(self, zone: ZoneIn) -> AirspaceZone:
        zone = with_defaults(zone)
        return AirspaceZone(
            organization_id=self.principal.organization_id,
            base_id=zone.base_id,
            name=zone.name,
            description=zone.description,
            kind=zone.kind,
            geometry=zone.geometry.model_dump(),
            radius_m=zone.radius_m,
            floor_m=zone.floor_m,
            ceiling_m=zone.ceiling_m,
            altitude_ref=zone.altitude_ref,
            windows=[w.model_dump(mode="json") for w in zone.windows]
            if zone.windows is not None
            else None,
            created_by=self.principal.actor_id,
        )

    async def list_zones(self, page: Page, base_id: uuid.UUID | None) -> Paged[AirspaceZone]:
        """Zones of the organisation, oldest first (with `base_id`: those applying there)."""
        return await self.repo.list_filtered(page, base_id)

    async def get(self, zone_id: uuid.UUID) -> AirspaceZone:
        """One zone (NotFound for another organisation's)."""
        return await self.repo.get(zone_id)

    async def create(self, zone: ZoneIn) -> AirspaceZone:
        """A new zone; 422 lists every problem."""
        problems = zone_problems(zone) + await self._base_problems(zone, "")
        if problems:
            raise rejected(problems)
        (row,) = await self.repo.add([self._row(zone)])
        await record(self.uow, self.principal, "zone.created", target=str(row.id), name=row.name)
        return row

    async def import_collection(self, body: FeatureCollectionIn) -> list[AirspaceZone]:
        """Every Feature of a FeatureCollection as a zone, all or none; 422 names each bad one."""
        problems: list[Problem] = []
        zones: list[ZoneIn] = []
        if not body.features:
            raise rejected([Problem("features", "the collection has no features", 0, 1)])
        for k, feature in enumerate(body.features):
            where = f"features[{k}]"
            if not isinstance(feature, dict) or feature.get("type") != "Feature":
                problems.append(Problem(f"{where}.type", "not a GeoJSON Feature"))
                continue
            props = feature.get("properties")
            if not isinstance(props, dict):
                problems.append(
                    Problem(f"{where}.properties", "a zone's fields go in its properties")
                )
                continue
            try:
                zone = ZoneIn.model_validate({**props, "geometry": feature.get("geometry")})
            except ValidationError as err:
                problems += pydantic_problems(err, where)
                continue
            found = zone_problems(zone, where) + await self._base_problems(zone, where)
            problems += found
            if not found:
                zones.append(zone)
        if problems:
            raise rejected(problems, code="import_rejected")
        rows = await self.repo.add([self._row(z) for z in zones])
        await record(self.uow, self.principal, "zone.imported", count=len(rows))
        return rows

    async def update(self, zone_id: uuid.UUID, changes: dict[str, Any]) -> AirspaceZone:
        """Apply a partial update, validating the zone as a whole."""
        row = await self.repo.get(zone_id)
        current = {
            "name": row.name,
            "description": row.description,
            "kind": row.kind,
            "geometry": row.geometry,
            "radius_m": row.radius_m,
            "floor_m": row.floor_m,
            "ceiling_m": row.ceiling_m,
            "altitude_ref": row.altitude_ref,
            "windows": row.windows,
            "base_id": row.base_id,
        }
        if (changes.get("geometry") or {}).get("type") == "Polygon":  # null: refused below
            current["radius_m"] = None  # a circle turned polygon loses its radius
        try:
            zone = ZoneIn.model_validate({**current, **changes})
        except ValidationError as err:
            raise rejected(pydantic_problems(err, "zone")) from err
        problems = zone_problems(zone)
        if problems:
            raise rejected(problems)
        fresh = self._row(zone)
        for key in current:
            setattr(row, key, getattr(fresh, key))
        await self.db.flush()
        await record(
            self.uow, self.principal, "zone.updated", target=str(row.id), changes=sorted(changes)
        )
        return row

    async def delete(self, zone_id: uuid.UUID) -> None:
        """Delete a zone."""
        row = await self.repo.get(zone_id)
        await record(self.uow, self.principal, "zone.deleted", target=str(row.id), name=row.name)
        await self.repo.delete(row)

    async def applicable(
        self, base_id: uuid.UUID | None, at: datetime | None = None
    ) -> list[ZoneShape]:
        """The zones a flight from `base_id` at `at` (now) must respect."""
        when = at or utcnow()
        rows = await self.repo.applicable(base_id)
        return [shape_of(z) for z in rows if is_active(z, when)]


async def flight_problems(
    db: Any, principal: Principal, mission: Any, base_id: uuid.UUID, at: datetime | None = None
) -> list[AirspaceProblem]:
    """The airspace problems of flying `mission` from `base_id` at `at` (now): the zones of
    the organisation and of the base that are active then, and the plan's own geoFence.

    The path starts and ends at the base (its position; unknown: the mission's home), so the
    legs to the mission and back are checked too. For code that holds a session but no unit of
    work (run creation, the run engine).
    """
    from server.missions.items import items_of

    rows = await ZoneRepository(db, principal).applicable(base_id)
    when = at or utcnow()
    zones = [shape_of(z) for z in rows if is_active(z, when)]
    home = await launch(db, principal, mission, base_id)
    return check_flight(items_of(mission.items), home, zones, mission.extras)


async def launch(db: Any, principal: Principal, mission: Any, base_id: uuid.UUID) -> Home | None:
    """Where a flight of `mission` from `base_id` starts and ends (missions/reach.py)."""
    from server.missions.build import home_of
    from server.missions.reach import launch_home

    base = await AssetRepository(db, principal).get(base_id)
    return launch_home(base.attributes, home_of(mission.home))


def refused(problems: list[AirspaceProblem], code: str = "airspace") -> Unprocessable:
    """The 422 naming every segment that breaks the airspace."""
    first = problems[0]
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return Unprocessable(
        f"the mission's path breaks the airspace: {first.what}{more}",
        code=code,
        details=[p.as_dict() for p in problems],
    )


async def flight_fence(
    db: Any, principal: Principal, mission: Any, base_id: uuid.UUID, at: datetime | None = None
) -> Fence | None:
    """The fence and rally points to upload for flying `mission` from `base_id` (None when
    neither the base's position nor the mission's home anchors a fence and a return point)."""
    from server.missions.items import items_of

    home = await launch(db, principal, mission, base_id)
    if home is None:
        return None
    rows = await ZoneRepository(db, principal).applicable(base_id)
    when = at or utcnow()
    zones = [shape_of(z) for z in rows if is_active(z, when)]
    return build_fence(
        items_of(mission.items), home, [*zones, *plan_fence_zones(mission.extras)], mission.extras
    )
