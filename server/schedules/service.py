"""Schedules: the API's decisions (ScheduleService) and the scheduler, which fires due schedules
exactly once, follows the missed-run policy and never retries blindly."""

from __future__ import annotations

import logging
import uuid
from datetime import timedelta
from typing import Any

from sqlalchemy.exc import IntegrityError

from server.assets.models import AssetKind
from server.assets.repository import AssetRepository
from server.kit.errors import AppError, Unprocessable
from server.kit.etag import NO_PRECONDITION, IfMatch
from server.kit.paging import Page, Paged
from server.kit.periodic import Periodic
from server.kit.principal import Principal, Role
from server.kit.service import Service
from server.kit.time import rfc3339, utcnow
from server.kit.uow import UnitOfWork
from server.missions.repository import MissionRepository
from server.runs.repository import RunRepository
from server.runs.service import create_run
from server.schedules.models import Schedule
from server.schedules.repository import ScheduleRepository, claim_due
from server.schedules.schemas import ScheduleCreate
from server.schedules.timing import TimingError, check_cron, decide, next_after, zone
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


class ScheduleService(Service):
    """Schedules of the caller's organisation."""

    def __init__(self, uow: UnitOfWork, principal: Principal, min_interval_s: int = 60) -> None:
        """`min_interval_s`: the shortest interval a schedule may have (a setting)."""
        super().__init__(uow, principal)
        self.min_interval_s = min_interval_s

    async def create(self, body: ScheduleCreate) -> Schedule:
        """A schedule bound to a mission, a UAV and a base, with its first due time."""
        await MissionRepository(self.db, self.principal).get(body.mission_id)
        assets = AssetRepository(self.db, self.principal)
        if (await assets.get(body.uav_id)).kind != AssetKind.uav:
            raise Unprocessable("uav_id is not a UAV", code="invalid_schedule")
        if (await assets.get(body.base_id)).kind != AssetKind.landing_base:
            raise Unprocessable("base_id is not a landing base", code="invalid_schedule")
        now = utcnow()
        try:
            zone(body.timezone)
            if body.kind == "once":
                if body.at is None:
                    raise TimingError("a one-shot schedule needs `at`")
                first = body.at
            elif body.kind == "interval":
                if body.interval_s is None:
                    raise TimingError("an interval schedule needs `interval_s`")
                if body.interval_s < self.min_interval_s:
                    raise TimingError(
                        f"interval_s must be at least {self.min_interval_s} s on this server"
                    )
                first = body.at or now + timedelta(seconds=body.interval_s)
            else:
                check_cron(body.cron or "")
                nxt = next_after("cron", now, cron=body.cron, tz=body.timezone)
                if nxt is None:  # next_after returns None only for a spent one-shot, never for cron
                    raise TimingError(f"cron expression {body.cron!r} has no next time")
                first = nxt
        except TimingError as err:
            raise Unprocessable(str(err), code="invalid_schedule") from err
        s = Schedule(
            organization_id=self.principal.organization_id,
            name=body.name,
            mission_id=body.mission_id,
            uav_id=body.uav_id,
            base_id=body.base_id,
            kind=body.kind,
            at=first if body.kind != "cron" else None,
            interval_s=body.interval_s,
            cron=body.cron,
            timezone=body.timezone,
            missed_policy=body.missed_policy,
            enabled=body.enabled,
            next_due_at=first,
            created_by=self.principal.actor_id,
            created_at=now,
            updated_at=now,
        )
        self.db.add(s)
        await self.db.flush()
        return s

    async def list_schedules(self, page: Page) -> Paged[Schedule]:
        """Schedules of the caller's organisation, oldest first."""
        return await ScheduleRepository(self.db, self.principal).list(page)

    async def get(self, schedule_id: uuid.UUID) -> Schedule:
        """One schedule (NotFound for another organisation's)."""
        return await ScheduleRepository(self.db, self.principal).get(schedule_id)

    async def update(
        self, schedule_id: uuid.UUID, changes: dict[str, Any], expect: IfMatch = NO_PRECONDITION
    ) -> Schedule:
        """Enable, disable, rename or change the missed-run policy (PreconditionFailed when
        `expect` names another version)."""
        s = await ScheduleRepository(self.db, self.principal).get(schedule_id, lock=True)
        expect.check(s.version, f"schedule {s.id}")
        for key, value in changes.items():
            if value is not None:
                setattr(s, key, value)
        s.updated_at = utcnow()
        await self.db.flush()
        return s

    async def delete(self, schedule_id: uuid.UUID, expect: IfMatch = NO_PRECONDITION) -> None:
        """Delete a schedule (its past runs stay)."""
        s = await ScheduleRepository(self.db, self.principal).get(schedule_id, lock=True)
        expect.check(s.version, f"schedule {s.id}")
        await self.db.delete(s)


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
                f"the run for {rfc3339(due)} was already started by another server process"
            )
        except AppError as err:
            s.last_fired_at = utcnow()
            s.last_result = f"could not start the run due {rfc3339(due)}: {err.message}"
            log.warning("schedule %s: %s", s.id, s.last_result)
