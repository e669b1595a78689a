"""All SQL of missions."""

from __future__ import annotations

from sqlalchemy.exc import IntegrityError

from server.kit.errors import Conflict
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository
from server.missions.models import Mission, MissionKind


class MissionRepository(ScopedRepository[Mission]):
    """Missions of the caller's organisation."""

    model = Mission
    noun = "mission"

    async def list_filtered(self, page: Page, kind: MissionKind | None) -> Paged[Mission]:
        """Missions of the caller's organisation, oldest first, optionally of one kind."""
        stmt = self.select().order_by(Mission.created_at, Mission.id)
        if kind:
            stmt = stmt.where(Mission.kind == kind)
        return await paginate(self.db, stmt, page)

    async def add(self, mission: Mission) -> Mission:
        """Insert a mission into the current unit of work."""
        self.db.add(mission)
        await self.db.flush()
        return mission

    async def delete(self, mission: Mission) -> None:
        """Delete a mission in the current unit of work; Conflict while runs still refer to it."""
        mission_id = mission.id  # the row cannot be read again once a flush failed
        await self.db.delete(mission)
        try:
            await self.db.flush()
        except IntegrityError as err:
            raise Conflict(
                f"mission {mission_id} is used by runs and cannot be deleted", code="mission_in_use"
            ) from err
