"""HTTP routes of runs and reports."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends

from server.deps import Operator, ServicesDep, UoW, Viewer
from server.kit.errors import Conflict, NotFound
from server.kit.openapi import errors
from server.kit.paging import PAGED, Paging
from server.kit.types import Timestamp
from server.runs.machine import State
from server.runs.schemas import (
    AbortRequest,
    FleetReport,
    RunCreate,
    RunOut,
    RunOutcome,
    RunReport,
)
from server.runs.service import RunService, run_out

router = APIRouter(tags=["runs"])


def _service(uow: UoW, principal: Viewer) -> RunService:
    return RunService(uow, principal)


def _operator_service(uow: UoW, principal: Operator) -> RunService:
    return RunService(uow, principal)


Runs = Annotated[RunService, Depends(_service)]
RunsOperator = Annotated[RunService, Depends(_operator_service)]


@router.post(
    "/api/v1/runs",
    status_code=201,
    response_model=RunOut,
    responses=errors(NotFound, Conflict),  # an id of nothing here; the UAV or base is busy
)
async def create_run(body: RunCreate, runs: RunsOperator) -> RunOut:
    """Start an autonomous run now (it checks availability first)."""
    return run_out(await runs.create(body.mission_id, body.uav_id, body.base_id))


@router.get("/api/v1/runs", response_model=list[RunOut], responses=PAGED)
async def list_runs(
    runs: Runs,
    pages: Paging,
    state: State | None = None,
    uav_id: uuid.UUID | None = None,
    outcome: RunOutcome | None = None,
) -> list[RunOut]:
    """Runs of the caller's organisation, newest first (by state, UAV or outcome)."""
    found = await runs.list_runs(pages.page, state, uav_id, outcome)
    pages.respond(found.total)
    return [run_out(r) for r in found.items]


@router.get("/api/v1/runs/{run_id}", response_model=RunOut)
async def get_run(run_id: uuid.UUID, runs: Runs) -> RunOut:
    """A run with its timeline."""
    return await runs.with_timeline(run_id)


@router.post(
    "/api/v1/runs/{run_id}/abort",
    status_code=202,
    response_model=RunOut,
    responses=errors(Conflict),
)
async def abort_run(run_id: uuid.UUID, body: AbortRequest, runs: RunsOperator) -> RunOut:
    """Ask the run to stop safely: before take-off the base closes; in flight the UAV returns and lands."""
    return run_out(await runs.abort(run_id, body.reason))


@router.get("/api/v1/runs/{run_id}/report", response_model=RunReport, operation_id="getRunReport")
async def run_report(run_id: uuid.UUID, runs: Runs, services: ServicesDep) -> RunReport:
    """The flight history of a run: timeline, track, battery used, landing error, outcome and cause."""
    return await runs.report(run_id, services.telemetry, services.settings.video_record_dir)


@router.get("/api/v1/reports/fleet", response_model=FleetReport, operation_id="getFleetReport")
async def fleet_report(
    runs: Runs, start: Timestamp | None = None, end: Timestamp | None = None
) -> FleetReport:
    """Runs in [start, end): success rate, failures by cause, mean flight time, per asset."""
    return await runs.fleet(start, end)
