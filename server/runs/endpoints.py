"""HTTP routes of runs and reports."""

from __future__ import annotations

import uuid
from datetime import datetime, timedelta

from fastapi import APIRouter, Query

from server.assets.repository import AssetRepository
from server.deps import DB, Operator, ServicesDep, Viewer
from server.kit.errors import Conflict, Unprocessable
from server.kit.time import utcnow
from server.runs import service
from server.runs.machine import FINAL, State
from server.runs.repository import RunRepository
from server.runs.schemas import AbortRequest, FleetReport, RunCreate, RunOut, RunReport

router = APIRouter(tags=["runs"])


@router.post("/api/v1/runs", status_code=201, response_model=RunOut)
async def create_run(body: RunCreate, principal: Operator, db: DB) -> RunOut:
    """Start an autonomous run now (it checks availability first)."""
    run = await service.create_run(
        RunRepository(db, principal),
        AssetRepository(db, principal),
        mission_id=body.mission_id,
        uav_id=body.uav_id,
        base_id=body.base_id,
        created_by=principal.actor_id,
    )
    return service.run_out(run)


@router.get("/api/v1/runs", response_model=list[RunOut])
async def list_runs(
    principal: Viewer,
    db: DB,
    state: State | None = None,
    uav_id: uuid.UUID | None = None,
    limit: int = Query(100, ge=1, le=1000),
    offset: int = Query(0, ge=0, le=10**9),
) -> list[RunOut]:
    """Runs of the caller's organisation, newest first."""
    rows = await RunRepository(db, principal).filtered(
        limit, offset, state.value if state else None, uav_id
    )
    return [service.run_out(r) for r in rows]


@router.get("/api/v1/runs/{run_id}", response_model=RunOut)
async def get_run(run_id: uuid.UUID, principal: Viewer, db: DB) -> RunOut:
    """A run with its timeline."""
    repo = RunRepository(db, principal)
    run = await repo.get(run_id)
    return service.run_out(run, await repo.timeline(run.id))


@router.post("/api/v1/runs/{run_id}/abort", status_code=202, response_model=RunOut)
async def abort_run(run_id: uuid.UUID, body: AbortRequest, principal: Operator, db: DB) -> RunOut:
    """Ask the run to stop safely: before take-off the base closes; in flight the UAV returns and lands."""
    run = await RunRepository(db, principal).get(run_id)
    if State(run.state) in FINAL:
        raise Conflict(f"run {run.id} has already ended ({run.state})", code="run_finished")
    run.abort_requested = True
    run.abort_reason = body.reason or f"requested by {principal.label}"
    run.updated_at = utcnow()
    await db.flush()
    return service.run_out(run)


@router.get("/api/v1/runs/{run_id}/report", response_model=RunReport)
async def run_report(
    run_id: uuid.UUID, principal: Viewer, services: ServicesDep, db: DB
) -> RunReport:
    """The flight history of a run: timeline, track, battery used, landing error, outcome and cause."""
    repo = RunRepository(db, principal)
    run = await repo.get(run_id)
    return await service.report(repo, services.telemetry, run)


@router.get("/api/v1/reports/fleet", response_model=FleetReport)
async def fleet_report(
    principal: Viewer, db: DB, start: datetime | None = None, end: datetime | None = None
) -> FleetReport:
    """Runs in [start, end): success rate, failures by cause, mean flight time, per asset."""
    end = end or utcnow()
    try:
        start = start or end - timedelta(days=30)
    except OverflowError as err:
        raise Unprocessable("end is too early for the default 30-day window; give start") from err
    if start.tzinfo is None or end.tzinfo is None or start >= end:
        raise Unprocessable("start and end need a time zone and start must be before end")
    runs = await RunRepository(db, principal).in_window(start, end)
    return service.fleet(runs, start, end)
