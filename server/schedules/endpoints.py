"""HTTP routes of schedules."""

from __future__ import annotations

import uuid
from datetime import timedelta

from fastapi import APIRouter, Query, Response

from server.assets.models import AssetKind
from server.assets.repository import AssetRepository
from server.deps import DB, Operator, Viewer
from server.kit.errors import Unprocessable
from server.kit.time import utcnow
from server.schedules.models import Schedule
from server.schedules.repository import ScheduleRepository
from server.schedules.schemas import ScheduleCreate, ScheduleOut, ScheduleUpdate
from server.schedules.timing import TimingError, check_cron, next_after, zone

router = APIRouter(tags=["schedules"])


@router.post("/api/v1/schedules", status_code=201, response_model=ScheduleOut)
async def create_schedule(body: ScheduleCreate, principal: Operator, db: DB) -> ScheduleOut:
    """Create a schedule bound to a mission, a UAV and a base."""
    from server.missions.repository import MissionRepository

    await MissionRepository(db, principal).get(body.mission_id)
    assets = AssetRepository(db, principal)
    if (await assets.get(body.uav_id)).kind != AssetKind.uav:
        raise Unprocessable("uav_id is not a UAV", code="invalid_schedule")
    if (await assets.get(body.base_id)).kind != AssetKind.landing_base:
        raise Unprocessable("base_id is not a landing base", code="invalid_schedule")
    now = utcnow()
    try:
        zone(body.timezone)
        if body.at is not None and body.at.tzinfo is None:
            raise TimingError("`at` needs a time zone offset (e.g. 2026-11-22T10:00:00Z)")
        if body.kind == "once":
            if body.at is None:
                raise TimingError("a one-shot schedule needs `at`")
            first = body.at
        elif body.kind == "interval":
            if body.interval_s is None:
                raise TimingError("an interval schedule needs `interval_s`")
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
        organization_id=principal.organization_id,
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
        created_by=principal.actor_id,
        created_at=now,
        updated_at=now,
    )
    db.add(s)
    await db.flush()
    return ScheduleOut.model_validate(s)


@router.get("/api/v1/schedules", response_model=list[ScheduleOut])
async def list_schedules(
    principal: Viewer,
    db: DB,
    limit: int = Query(100, ge=1, le=1000),
    offset: int = Query(0, ge=0, le=10**9),
) -> list[ScheduleOut]:
    """Schedules of the caller's organisation."""
    return [
        ScheduleOut.model_validate(s)
        for s in await ScheduleRepository(db, principal).list(limit, offset)
    ]


@router.get("/api/v1/schedules/{schedule_id}", response_model=ScheduleOut)
async def get_schedule(schedule_id: uuid.UUID, principal: Viewer, db: DB) -> ScheduleOut:
    """One schedule."""
    return ScheduleOut.model_validate(await ScheduleRepository(db, principal).get(schedule_id))


@router.patch("/api/v1/schedules/{schedule_id}", response_model=ScheduleOut)
async def update_schedule(
    schedule_id: uuid.UUID, body: ScheduleUpdate, principal: Operator, db: DB
) -> ScheduleOut:
    """Enable, disable, rename or change the missed-run policy."""
    s = await ScheduleRepository(db, principal).get(schedule_id)
    for key, value in body.model_dump(exclude_unset=True).items():
        if value is not None:
            setattr(s, key, value)
    s.updated_at = utcnow()
    await db.flush()
    return ScheduleOut.model_validate(s)


@router.delete("/api/v1/schedules/{schedule_id}", status_code=204, response_class=Response)
async def delete_schedule(schedule_id: uuid.UUID, principal: Operator, db: DB) -> Response:
    """Delete a schedule (its past runs stay)."""
    s = await ScheduleRepository(db, principal).get(schedule_id)
    await db.delete(s)
    return Response(status_code=204)
