"""HTTP routes of missions: CRUD, QGroundControl/WPL import and export, validation."""

from __future__ import annotations

import asyncio
import uuid
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.responses import JSONResponse

from server.deps import Operator, SettingsDep, UoW, Viewer
from server.kit.errors import Conflict, UnsupportedMediaType
from server.kit.etag import CREATED_TAGGED, TAGGED, IfMatchDep, tag
from server.kit.openapi import errors
from server.kit.paging import PAGED, Paging
from server.missions import qgc, wpl
from server.missions.models import Mission, MissionKind
from server.missions.schemas import (
    MissionCreate,
    MissionOut,
    MissionUpdate,
    ValidateRequest,
    ValidationReport,
)
from server.missions.service import MissionService, estimate, limits_from, rejected
from server.missions.upload import read_import

router = APIRouter(tags=["missions"])


def _service(uow: UoW, principal: Viewer, settings: SettingsDep) -> MissionService:
    return MissionService(uow, principal, limits_from(settings))


def _operator_service(uow: UoW, principal: Operator, settings: SettingsDep) -> MissionService:
    return MissionService(uow, principal, limits_from(settings))


Missions = Annotated[MissionService, Depends(_service)]
MissionsOperator = Annotated[MissionService, Depends(_operator_service)]


def _out(mission: Mission) -> MissionOut:
    return MissionOut.model_validate(
        {
            "id": mission.id,
            "organization_id": mission.organization_id,
            "name": mission.name,
            "description": mission.description,
            "kind": mission.kind,
            "source": mission.source,
            "items": mission.items,
            "home": mission.home,
            "speed_mps": mission.speed_mps,
            "survey": mission.survey,
            "survey_plan": mission.survey_plan,
            "extras": mission.extras or {},
            "estimate": estimate(mission).as_dict(),
            "created_at": mission.created_at,
            "updated_at": mission.updated_at,
        }
    )


@router.get("/api/v1/missions", response_model=list[MissionOut], responses=PAGED)
async def list_missions(
    missions: Missions, pages: Paging, kind: MissionKind | None = None
) -> list[MissionOut]:
    """Missions of the caller's organisation, oldest first."""
    found = await missions.list_missions(pages.page, kind)
    pages.respond(found.total)
    # validating and estimating many missions is CPU work: off the event loop
    return await asyncio.to_thread(lambda: [_out(m) for m in found.items])


@router.post(
    "/api/v1/missions", status_code=201, response_model=MissionOut, responses=CREATED_TAGGED
)
async def create_mission(
    body: MissionCreate, missions: MissionsOperator, response: Response
) -> MissionOut:
    """Create a waypoints or survey mission (operators); 422 lists every problem."""
    mission = await missions.create(
        name=body.name,
        description=body.description,
        kind=body.kind,
        items=body.items,
        survey=body.survey,
        home=body.home,
        speed_mps=body.speed_mps,
    )
    tag(response, mission.version)
    return _out(mission)


WPL_FILE = {"type": "string", "format": "binary", "description": "a QGC WPL 110 waypoint file"}
IMPORT_BODY = {
    "required": True,
    "content": {
        "application/json": {
            "schema": {"type": "object", "description": "a QGroundControl .plan file"}
        },
        # the file's bytes as uploaded (UTF-8 text); `binary` so generated clients send them as is
        "text/plain": {"schema": WPL_FILE},
        wpl.MEDIA_TYPE: {"schema": WPL_FILE},
    },
}


@router.post(
    "/api/v1/missions/import",
    status_code=201,
    response_model=MissionOut,
    responses={**CREATED_TAGGED, **errors(UnsupportedMediaType)},
    openapi_extra={"requestBody": IMPORT_BODY},
)
async def import_mission(
    missions: MissionsOperator,
    request: Request,
    response: Response,
    name: str | None = Query(None, min_length=1, max_length=100),
    description: str = Query("", max_length=2000),
) -> MissionOut:
    """Import a QGroundControl .plan (JSON) or a WPL 110 file (text); 422 names every item refused."""
    body = await request.body()  # at most AEROBASE_MAX_IMPORT_BYTES (server/kit/bodylimit.py)
    try:
        imported, source = await read_import(
            body, request.headers.get("content-type", ""), missions.limits.max_items
        )
    except qgc.ImportRejected as err:
        raise rejected(err.problems, code="import_rejected") from err
    label = {"qgc": "QGroundControl plan", "wpl": "waypoint file"}[source]
    title = (name or "").strip() or f"imported {label}"
    mission = await missions.import_file(
        imported, name=title, description=description, source=source
    )
    tag(response, mission.version)
    return _out(mission)


@router.get("/api/v1/missions/{mission_id}", response_model=MissionOut, responses=TAGGED)
async def get_mission(mission_id: uuid.UUID, missions: Missions, response: Response) -> MissionOut:
    """One mission of the caller's organisation, its ETag in the header."""
    mission = await missions.get(mission_id)
    tag(response, mission.version)
    return _out(mission)


@router.patch(
    "/api/v1/missions/{mission_id}",
    response_model=MissionOut,
    responses=TAGGED,
)
async def update_mission(
    mission_id: uuid.UUID,
    body: MissionUpdate,
    missions: MissionsOperator,
    expect: IfMatchDep,
    response: Response,
) -> MissionOut:
    """Change a mission (operators); items and survey are validated and compiled again.
    With `If-Match`, only the version it names is changed (else 412)."""
    changes = body.model_dump(exclude_unset=True)
    mission = await missions.update(mission_id, changes, body, expect)
    tag(response, mission.version)
    return _out(mission)


@router.delete(
    "/api/v1/missions/{mission_id}",
    status_code=204,
    response_class=Response,
    responses=errors(Conflict),  # 409: runs still refer to it
)
async def delete_mission(
    mission_id: uuid.UUID, missions: MissionsOperator, expect: IfMatchDep
) -> Response:
    """Delete a mission (operators); with `If-Match`, only the version it names (else 412)."""
    await missions.delete(mission_id, expect)
    return Response(status_code=204)


@router.get(
    "/api/v1/missions/{mission_id}/export",
    responses={
        200: {
            "content": {"application/json": {}, "text/plain": {}},
            "description": "a QGroundControl .plan (qgc) or QGC WPL 110 text (wpl)",
        }
    },
)
async def export_mission(
    mission_id: uuid.UUID, missions: Missions, format: Literal["qgc", "wpl"] = "qgc"
) -> Response:
    """The mission as a QGroundControl .plan file or a WPL 110 waypoint file."""
    mission = await missions.get(mission_id)
    content, filename = MissionService.export(mission, format)
    headers = {"Content-Disposition": f'attachment; filename="{filename}"'}
    if isinstance(content, dict):
        return JSONResponse(content, headers=headers)
    return Response(content, media_type="text/plain; charset=utf-8", headers=headers)


@router.post("/api/v1/missions/{mission_id}/validate", response_model=ValidationReport)
async def validate_mission(
    mission_id: uuid.UUID, body: ValidateRequest, missions: MissionsOperator
) -> ValidationReport:
    """Check a mission against the limits, the airspace (its path: every segment, the return leg)
    and, with `uav_id`, the UAV's endurance and reach; with `base_id`, flown from that base
    (operators)."""
    mission = await missions.get(mission_id)
    uav = await missions.uav(body.uav_id)
    base = await missions.base(body.base_id)
    zones = await missions.zones(body.base_id, body.at)
    report = await asyncio.to_thread(missions.check, mission, uav, zones, base)
    return ValidationReport.model_validate(report)
