"""HTTP routes of schedules."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.deps import Operator, SettingsDep, UoW, Viewer
from server.kit.errors import NotFound
from server.kit.etag import CREATED_TAGGED, TAGGED, IfMatchDep, tag
from server.kit.openapi import errors
from server.kit.paging import PAGED, Paging
from server.schedules.schemas import ScheduleCreate, ScheduleOut, ScheduleUpdate
from server.schedules.service import ScheduleService

router = APIRouter(tags=["schedules"])


def _service(uow: UoW, principal: Viewer) -> ScheduleService:
    return ScheduleService(uow, principal)


def _operator_service(uow: UoW, principal: Operator, settings: SettingsDep) -> ScheduleService:
    return ScheduleService(uow, principal, settings.schedule_min_interval_s)


Schedules = Annotated[ScheduleService, Depends(_service)]
SchedulesOperator = Annotated[ScheduleService, Depends(_operator_service)]


@router.post(
    "/api/v1/schedules",
    status_code=201,
    response_model=ScheduleOut,
    responses={**CREATED_TAGGED, **errors(NotFound)},  # mission_id, uav_id or base_id of nothing
)
async def create_schedule(
    body: ScheduleCreate, schedules: SchedulesOperator, response: Response
) -> ScheduleOut:
    """Create a schedule bound to a mission, a UAV and a base."""
    schedule = await schedules.create(body)
    tag(response, schedule.version)
    return ScheduleOut.model_validate(schedule)


@router.get("/api/v1/schedules", response_model=list[ScheduleOut], responses=PAGED)
async def list_schedules(schedules: Schedules, pages: Paging) -> list[ScheduleOut]:
    """Schedules of the caller's organisation, oldest first."""
    found = await schedules.list_schedules(pages.page)
    pages.respond(found.total)
    return [ScheduleOut.model_validate(s) for s in found.items]


@router.get("/api/v1/schedules/{schedule_id}", response_model=ScheduleOut, responses=TAGGED)
async def get_schedule(
    schedule_id: uuid.UUID, schedules: Schedules, response: Response
) -> ScheduleOut:
    """One schedule, its ETag in the header."""
    schedule = await schedules.get(schedule_id)
    tag(response, schedule.version)
    return ScheduleOut.model_validate(schedule)


@router.patch(
    "/api/v1/schedules/{schedule_id}",
    response_model=ScheduleOut,
    responses=TAGGED,
)
async def update_schedule(
    schedule_id: uuid.UUID,
    body: ScheduleUpdate,
    schedules: SchedulesOperator,
    expect: IfMatchDep,
    response: Response,
) -> ScheduleOut:
    """Enable, disable, rename or change the missed-run policy; with `If-Match`, only the
    version it names (else 412)."""
    changes = body.model_dump(exclude_unset=True)
    schedule = await schedules.update(schedule_id, changes, expect)
    tag(response, schedule.version)
    return ScheduleOut.model_validate(schedule)


@router.delete(
    "/api/v1/schedules/{schedule_id}",
    status_code=204,
    response_class=Response,
)
async def delete_schedule(
    schedule_id: uuid.UUID, schedules: SchedulesOperator, expect: IfMatchDep
) -> Response:
    """Delete a schedule (its past runs stay); with `If-Match`, only the version it names."""
    await schedules.delete(schedule_id, expect)
    return Response(status_code=204)
