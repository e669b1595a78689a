"""All SQL of missions."""

from __future__ import annotations

from sqlalchemy import exists, select

from server.kit.db import delete_unless_referred
from server.kit.errors import Conflict
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository
from server.missions.models import Mission, MissionKind
from server.runs.models import Run


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
        """Delete a mission in the current unit of work; Conflict while runs still refer to it
        (`delete_unless_referred`)."""
        mission_id = mission.id
        in_use = Conflict(
            f"mission {mission_id} is used by runs and cannot be deleted", code="mission_in_use"
        )
        referred = select(exists().where(Run.mission_id == mission_id))  # unscoped: its id
        await delete_unless_referred(self.db, mission, referred, in_use)
