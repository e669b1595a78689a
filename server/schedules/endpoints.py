"""HTTP routes of schedules."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.deps import Operator, UoW, Viewer
from server.kit.paging import PAGED, Paging
from server.schedules.schemas import ScheduleCreate, ScheduleOut, ScheduleUpdate
from server.schedules.service import ScheduleService

router = APIRouter(tags=["schedules"])


def _service(uow: UoW, principal: Viewer) -> ScheduleService:
    return ScheduleService(uow, principal)


def _operator_service(uow: UoW, principal: Operator) -> ScheduleService:
    return ScheduleService(uow, principal)


Schedules = Annotated[ScheduleService, Depends(_service)]
SchedulesOperator = Annotated[ScheduleService, Depends(_operator_service)]


@router.post("/api/v1/schedules", status_code=201, response_model=ScheduleOut)
async def create_schedule(body: ScheduleCreate, schedules: SchedulesOperator) -> ScheduleOut:
    """Create a schedule bound to a mission, a UAV and a base."""
    return ScheduleOut.model_validate(await schedules.create(body))


@router.get("/api/v1/schedules", response_model=list[ScheduleOut], responses=PAGED)
async def list_schedules(schedules: Schedules, pages: Paging) -> list[ScheduleOut]:
    """Schedules of the caller's organisation, oldest first."""
    found = await schedules.list_schedules(pages.page)
    pages.respond(found.total)
    return [ScheduleOut.model_validate(s) for s in found.items]


@router.get("/api/v1/schedules/{schedule_id}", response_model=ScheduleOut)
async def get_schedule(schedule_id: uuid.UUID, schedules: Schedules) -> ScheduleOut:
    """One schedule."""
    return ScheduleOut.model_validate(await schedules.get(schedule_id))


@router.patch("/api/v1/schedules/{schedule_id}", response_model=ScheduleOut)
async def update_schedule(
    schedule_id: uuid.UUID, body: ScheduleUpdate, schedules: SchedulesOperator
) -> ScheduleOut:
    """Enable, disable, rename or change the missed-run policy."""
    changes = body.model_dump(exclude_unset=True)
    return ScheduleOut.model_validate(await schedules.update(schedule_id, changes))


@router.delete("/api/v1/schedules/{schedule_id}", status_code=204, response_class=Response)
async def delete_schedule(schedule_id: uuid.UUID, schedules: SchedulesOperator) -> Response:
    """Delete a schedule (its past runs stay)."""
    await schedules.delete(schedule_id)
    return Response(status_code=204)
