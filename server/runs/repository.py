"""All SQL of runs: scoped reads for the API, leases and observations for the engine."""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from datetime import datetime
from typing import Any

from sqlalchemy import delete, or_, select, update
from sqlalchemy.ext.asyncio import AsyncSession

from server.commands.models import AssetCommand
from server.kit import metrics
from server.kit.errors import NotFound
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository, scoped
from server.kit.time import utcnow
from server.runs.machine import FINAL, Action
from server.runs.models import Run, RunStepCommand, RunTransition
from server.telemetry.models import AssetEvent

FINAL_VALUES = [s.value for s in FINAL]


class RunRepository(ScopedRepository[Run]):
    """Runs of the caller's organisation."""

    model = Run
    noun = "run"

    async def filtered(
        self, page: Page, state: str | None, uav_id: uuid.UUID | None, outcome: str | None = None
    ) -> Paged[Run]:
        """Newest first, optionally by state, UAV or outcome."""
        stmt = self.select().order_by(Run.created_at.desc(), Run.id)
        if state:
            stmt = stmt.where(Run.state == state)
        if outcome:
            stmt = stmt.where(Run.outcome == outcome)
        if uav_id:
            stmt = stmt.where(Run.uav_id == uav_id)
        return await paginate(self.db, stmt, page)

    async def in_window(self, start: datetime, end: datetime) -> list[Run]:
        """Runs created in [start, end)."""
        stmt = (
            self.select()
            .where(Run.created_at >= start, Run.created_at < end)
            .order_by(Run.created_at)
        )
        return list((await self.db.execute(stmt)).scalars())

    async def busy(self, asset_ids: list[uuid.UUID]) -> Run | None:
        """An unfinished run using any of these assets."""
        stmt = (
            self.select()
            .where(
                Run.state.not_in(FINAL_VALUES),
                or_(Run.uav_id.in_(asset_ids), Run.base_id.in_(asset_ids)),
            )
            .limit(1)
        )
        return (await self.db.execute(stmt)).scalar_one_or_none()

    async def with_timeline(self, run_id: uuid.UUID) -> tuple[Run, list[RunTransition]]:
        """A run and its transitions read in ONE statement, so one snapshot: two reads under READ
        COMMITTED could return the run before a commit and its timeline after it (a new timeline
        entry beside the reason it replaced). NotFound outside the caller's organisation."""
        stmt = (
            self.select()
            .where(Run.id == run_id)
            .outerjoin(RunTransition, RunTransition.run_id == Run.id)
            .add_columns(RunTransition)
            .order_by(RunTransition.at)
            .execution_options(populate_existing=True)
        )
        rows = (await self.db.execute(stmt)).all()
        if not rows:
            raise NotFound(f"{self.noun} {run_id} not found")
        return rows[0][0], [t for _, t in rows if t is not None]

    async def flight_events(self, run: Run, name: str) -> list[AssetEvent]:
        """The UAV's events called `name` during a run's flight, oldest first."""
        stmt = scoped(AssetEvent, self.principal).where(
            AssetEvent.asset_id == run.uav_id,
            AssetEvent.name == name,
            AssetEvent.created_at >= (run.flight_started_at or run.created_at),
        )
        if run.finished_at is not None:
            stmt = stmt.where(AssetEvent.created_at <= run.finished_at)
        return list((await self.db.execute(stmt.order_by(AssetEvent.created_at))).scalars())

    async def flight_so_far(self, run: Run) -> float | None:
        """A flying run's time in the air by the UAV's own clock: its `took_off` to now (its
        `landed` once reported)."""
        took_off = await self.flight_events(run, "took_off")
        if not took_off:
            return None
        landed = [e.ts for e in await self.flight_events(run, "landed") if e.ts >= took_off[0].ts]
        end = landed[0] if landed else utcnow()
        return max(0.0, (end - took_off[0].ts).total_seconds())

    async def landing_events(self, run: Run) -> tuple[AssetEvent | None, AssetEvent | None]:
        """The UAV's last `landed` and the base's first `landing_confirmed` event of a run's flight."""

        def during(asset_id: uuid.UUID, name: str) -> Any:
            stmt = scoped(AssetEvent, self.principal).where(
                AssetEvent.asset_id == asset_id,
                AssetEvent.name == name,
                AssetEvent.created_at >= (run.flight_started_at or run.created_at),
            )
            if run.finished_at is not None:
                stmt = stmt.where(AssetEvent.created_at <= run.finished_at)
            return stmt

        landed = during(run.uav_id, "landed").order_by(AssetEvent.created_at.desc()).limit(1)
        confirmed = (
            during(run.base_id, "landing_confirmed").order_by(AssetEvent.created_at).limit(1)
        )
        return (
            (await self.db.execute(landed)).scalars().first(),
            (await self.db.execute(confirmed)).scalars().first(),
        )


def note(db: AsyncSession, run: Run, to_state: str, reason: str, cause: str, at: datetime) -> None:
    """Add an entry to a run's timeline, from the state it is in now (to the same state for a
    note that is not a step: a settled close, a lease takeover)."""
    db.add(
        RunTransition(
            run_id=run.id,
            at=at,
            from_state=run.state,
            to_state=to_state,
            reason=reason,
            cause=cause,
        )
    )


async def claim(
    db: AsyncSession, owner: str, now: datetime, until: datetime, limit: int = 50
) -> list[uuid.UUID]:
    """Lease the runs this process will drive, unleased or ours: unfinished, with actions still to
    issue, or finished with safe commands (the close on the way out) still to be settled."""
    stmt = (
        select(Run)  # unscoped: the engine drives every organisation's runs
        .where(
            or_(
                Run.state.not_in(FINAL_VALUES),
                Run.actions_issued.is_(False),
                Run.id.in_(select(RunStepCommand.run_id)),  # unscoped: engine
            ),
            or_(Run.lease_until < now, Run.lease_owner == owner),
        )
        .order_by(Run.created_at)
        .limit(limit)
        # FOR NO KEY UPDATE: a mission's DELETE may check (KEY SHARE) the runs referring to it
        .with_for_update(skip_locked=True, key_share=True)
    )
    runs = list((await db.execute(stmt)).scalars())
    for run in runs:
        if run.lease_owner not in (None, owner):
            # the holder died (a clean stop hands its leases back): say so in the run's timeline
            metrics.LEASE_TAKEOVERS.inc()
            note(
                db,
                run,
                run.state,
                f"replica {owner} took the run over from {run.lease_owner}, whose lease ran out",
                "lease_takeover",
                now,
            )
        run.lease_owner, run.lease_until = owner, until
    return [r.id for r in runs]


async def release(db: AsyncSession, owner: str, now: datetime) -> None:
    """Hand back every lease `owner` holds (a clean stop), so another replica takes over at once."""
    stmt = (
        update(Run)
        .where(Run.lease_owner == owner)
        .values(lease_owner=None, lease_until=now)
        .execution_options(synchronize_session=False)
    )
    await db.execute(stmt)


async def lock(db: AsyncSession, run_id: uuid.UUID) -> Run | None:
    """A run, locked for the rest of the transaction (FOR NO KEY UPDATE: the engine never changes
    a run's keys, and a lock that blocked KEY SHARE deadlocked with a mission's DELETE, whose
    RESTRICT check waited for the run while the engine's next UPDATE re-checked the mission)."""
    stmt = select(Run).where(Run.id == run_id).with_for_update(key_share=True)  # unscoped: engine
    return (await db.execute(stmt)).scalar_one_or_none()


async def commands_by_id(db: AsyncSession, ids: list[uuid.UUID]) -> dict[uuid.UUID, AssetCommand]:
    """Commands the run issued."""
    if not ids:
        return {}
    stmt = select(AssetCommand).where(
        AssetCommand.id.in_(ids)
    )  # unscoped: engine, ids from the run itself
    return {c.id: c for c in (await db.execute(stmt)).scalars()}


async def event_names_since(db: AsyncSession, asset_id: uuid.UUID, since: datetime) -> list[str]:
    """Names of the events an asset reported that reached the server since `since`."""
    stmt = (
        select(AssetEvent.name)
        .where(
            AssetEvent.asset_id == asset_id,  # unscoped: engine
            AssetEvent.created_at >= since,
        )
        .order_by(AssetEvent.created_at)
    )
    return list((await db.execute(stmt)).scalars())


async def step_commands(db: AsyncSession, run_id: uuid.UUID) -> list[RunStepCommand]:
    """The commands of a run's current step, in the order they are issued."""
    stmt = (
        select(RunStepCommand)  # unscoped: engine, a run it holds the lock of
        .where(RunStepCommand.run_id == run_id)
        .order_by(RunStepCommand.position)
    )
    return list((await db.execute(stmt)).scalars())


async def replace_step_commands(
    db: AsyncSession, run_id: uuid.UUID, actions: Sequence[Action]
) -> list[RunStepCommand]:
    """A new step's commands, all pending: one row per distinct action, in order."""
    await db.execute(
        delete(RunStepCommand).where(RunStepCommand.run_id == run_id)
    )  # unscoped: engine, a run it holds the lock of
    rows: dict[str, RunStepCommand] = {}
    for action in actions:
        rows.setdefault(
            action.key,
            RunStepCommand(
                run_id=run_id, position=len(rows), target=action.target, command=action.name
            ),
        )
    db.add_all(rows.values())
    await db.flush()
    return list(rows.values())


async def flying_exit_cause(db: AsyncSession, run_id: uuid.UUID) -> str:
    """The cause of the run's step out of `flying` ("" for a mission finished or none yet)."""
    stmt = (
        select(RunTransition.cause)  # unscoped: engine, a run it holds the lock of
        .where(RunTransition.run_id == run_id, RunTransition.from_state == "flying")
        .where(RunTransition.to_state != "flying")
        .order_by(RunTransition.at)
        .limit(1)
    )
    return (await db.execute(stmt)).scalar_one_or_none() or ""


async def operator_returned(db: AsyncSession, uav_id: uuid.UUID, since: datetime) -> bool:
    """A person (not a run) sent the UAV a `return_to_base` or `abort` since `since`."""
    stmt = (
        select(AssetCommand.id)  # unscoped: engine
        .where(
            AssetCommand.asset_id == uav_id,
            AssetCommand.name.in_(("return_to_base", "abort")),
            AssetCommand.created_at >= since,
            or_(AssetCommand.created_by.is_(None), AssetCommand.created_by.not_like("run:%")),
        )
        .limit(1)
    )
    return (await db.execute(stmt)).first() is not None


async def reported_flight_s(db: AsyncSession, uav_id: uuid.UUID, since: datetime) -> float | None:
    """Take-off to touchdown as the UAV reported them (its `took_off` and the first `landed`
    after it, by the UAV's own clock), for a flight that began at `since`; None without both."""
    stmt = (
        select(AssetEvent.name, AssetEvent.ts)  # unscoped: engine
        .where(
            AssetEvent.asset_id == uav_id,
            AssetEvent.name.in_(("took_off", "landed")),
            AssetEvent.created_at >= since,
        )
        .order_by(AssetEvent.ts)
    )
    rows = (await db.execute(stmt)).all()
    took_off = next((ts for name, ts in rows if name == "took_off"), None)
    if took_off is None:
        return None
    landed = next((ts for name, ts in rows if name == "landed" and ts >= took_off), None)
    return None if landed is None else max(0.0, (landed - took_off).total_seconds())
