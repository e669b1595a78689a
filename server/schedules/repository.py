"""All SQL of schedules."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from server.kit.scope import ScopedRepository
from server.schedules.models import Schedule


class ScheduleRepository(ScopedRepository[Schedule]):
    """Schedules of the caller's organisation."""

    model = Schedule
    noun = "schedule"


async def claim_due(db: AsyncSession, now: datetime, limit: int = 20) -> list[Schedule]:
    """Due schedules, locked so that one process fires each due time (SKIP LOCKED on PostgreSQL)."""
    stmt = (
        select(Schedule)  # unscoped: the scheduler serves every organisation
        .where(
            Schedule.enabled.is_(True),
            Schedule.next_due_at.is_not(None),
            Schedule.next_due_at <= now,
        )
        .order_by(Schedule.next_due_at)
        .limit(limit)
        .with_for_update(skip_locked=True)
    )
    return list((await db.execute(stmt)).scalars())
