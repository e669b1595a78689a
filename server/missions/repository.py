"""All SQL of missions."""

from __future__ import annotations

from sqlalchemy import exists, select
from sqlalchemy.exc import DBAPIError, IntegrityError

from server.kit.db import sqlstate
from server.kit.errors import Conflict
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository
from server.missions.models import Mission, MissionKind
from server.runs.models import Run

DEADLOCK = "40P01"  # PostgreSQL's deadlock_detected


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
        """Delete a mission in the current unit of work; Conflict while runs still refer to it.

        Runs are looked for first, without locks: a DELETE whose RESTRICT check meets a run row
        locked by the run engine waits for it, while the engine's own foreign-key check waits for
        the mission (PostgreSQL reports a deadlock). Only a run created in the instant between
        the look and the DELETE can still meet it; that deadlock is the same answer, 409."""
        mission_id = mission.id  # the row cannot be read again once a flush failed
        in_use = Conflict(
            f"mission {mission_id} is used by runs and cannot be deleted", code="mission_in_use"
        )
        referred = select(exists().where(Run.mission_id == mission_id))  # unscoped: its id
        if await self.db.scalar(referred):
            raise in_use
        await self.db.delete(mission)
        try:
            await self.db.flush()
        except IntegrityError as err:
            raise in_use from err
        except DBAPIError as err:
            if sqlstate(err) == DEADLOCK:
                raise in_use from err
            raise
