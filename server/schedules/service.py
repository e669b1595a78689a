"""The scheduler: fires due schedules exactly once, follows the missed-run policy, never retries blindly."""

from __future__ import annotations

import logging
import uuid
from typing import Any

from sqlalchemy.exc import IntegrityError

from server.assets.repository import AssetRepository
from server.kit.errors import AppError
from server.kit.periodic import Periodic
from server.kit.scope import Principal
from server.kit.time import utcnow
from server.organizations.models import Role
from server.runs.repository import RunRepository
from server.runs.service import create_run
from server.schedules.models import Schedule
from server.schedules.repository import claim_due
from server.schedules.timing import decide, next_after
from server.services import Services

log = logging.getLogger(__name__)


def advance_schedule(s: Schedule, after: Any) -> None:
    """Set the next due time after `after`; a spent one-shot is disabled."""
    s.next_due_at = next_after(
        s.kind,
        after,
        at=s.at,
        interval_s=s.interval_s,
        cron=s.cron,
        tz=s.timezone,
        anchor=s.next_due_at or s.at,
    )
    if s.next_due_at is None:
        s.enabled = False


class Scheduler:
    """The per-process loop; every replica runs one, the row lock makes each due time fire once."""

    def __init__(self, services: Services, grace_s: float = 60.0, tick_s: float = 1.0) -> None:
        """Fire schedules through `services` (its sessionmaker), every `tick_s` seconds."""
        self.services = services
        self.grace_s = grace_s
        self._periodic = Periodic("scheduler", self.tick, tick_s)

    def start(self) -> None:
        """Start the loop."""
        self._periodic.start()

    async def stop(self) -> None:
        """Stop the loop."""
        await self._periodic.stop()

    async def tick(self) -> None:
        """Fire every due schedule once."""
        now = utcnow()
        async with self.services.sessionmaker() as db:
            for s in await claim_due(db, now):
                firing = decide(s.next_due_at, now, s.missed_policy, self.grace_s)  # type: ignore[arg-type]
                s.last_result = firing.note
                if firing.fire:
                    await self._fire(db, s, firing.scheduled_for, firing.note)
                advance_schedule(s, now)
                s.updated_at = now
            await db.commit()

    async def _fire(self, db: Any, s: Schedule, due: Any, note: str) -> None:
        system = Principal(
            kind="user",
            session_id=uuid.UUID(int=0),
            organization_id=s.organization_id,
            role=Role.admin,
            label=f"schedule {s.name}",
        )
        try:
            async with db.begin_nested():
                run = await create_run(
                    RunRepository(db, system),
                    AssetRepository(db, system),
                    mission_id=s.mission_id,
                    uav_id=s.uav_id,
                    base_id=s.base_id,
                    created_by=f"schedule:{s.id}",
                    schedule_id=s.id,
                    scheduled_for=due,
                )
            s.last_run_id, s.last_fired_at = run.id, utcnow()
            s.last_result = f"started run {run.id} ({note})"
            log.info("schedule %s started run %s for %s", s.id, run.id, due)
        except IntegrityError:
            s.last_result = (
                f"the run for {due.isoformat()} was already started by another server process"
            )
        except AppError as err:
            s.last_fired_at = utcnow()
            s.last_result = f"could not start the run due {due.isoformat()}: {err.message}"
            log.warning("schedule %s: %s", s.id, s.last_result)
