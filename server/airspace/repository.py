"""All SQL of airspace zones."""

from __future__ import annotations

import uuid

from sqlalchemy import or_

from server.airspace.models import AirspaceZone
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository


class ZoneRepository(ScopedRepository[AirspaceZone]):
    """Zones of the caller's organisation."""

    model = AirspaceZone
    noun = "zone"

    async def list_filtered(self, page: Page, base_id: uuid.UUID | None) -> Paged[AirspaceZone]:
        """Zones oldest first, with their total; with `base_id`, those that apply to that base's
        flights."""
        stmt = self.select().order_by(AirspaceZone.created_at, AirspaceZone.id)
        if base_id is not None:
            stmt = stmt.where(or_(AirspaceZone.base_id.is_(None), AirspaceZone.base_id == base_id))
        return await paginate(self.db, stmt, page)

    async def applicable(self, base_id: uuid.UUID | None) -> list[AirspaceZone]:
        """Every zone of the organisation and those of the base (`base_id`), at any time."""
        stmt = self.select().order_by(AirspaceZone.created_at, AirspaceZone.id)
        if base_id is None:
            stmt = stmt.where(AirspaceZone.base_id.is_(None))
        else:
            stmt = stmt.where(or_(AirspaceZone.base_id.is_(None), AirspaceZone.base_id == base_id))
        return list((await self.db.execute(stmt)).scalars())

    async def add(self, zones: list[AirspaceZone]) -> list[AirspaceZone]:
        """Insert zones into the current unit of work."""
        self.db.add_all(zones)
        await self.db.flush()
        return zones

    async def delete(self, zone: AirspaceZone) -> None:
        """Delete a zone in the current unit of work."""
        await self.db.delete(zone)
        await self.db.flush()
