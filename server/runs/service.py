"""Decisions about runs requested through the API: creation, abort, reports."""

from __future__ import annotations

import asyncio
import math
import uuid
from collections import Counter, defaultdict
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from server.airspace.service import flight_problems, refused
from server.assets.models import AssetKind
from server.assets.repository import AssetRepository
from server.kit.errors import Conflict, Unprocessable
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.runs.machine import FINAL, State
from server.runs.models import Run
from server.runs.progress import progress_payload
from server.runs.repository import RunRepository
from server.runs.reserve import return_model
from server.runs.schemas import (
    AssetSummary,
    BreachOut,
    FleetReport,
    LandingReport,
    RunOut,
    RunOutcome,
    RunReport,
    TransitionOut,
)
from server.telemetry.models import AssetEvent
from server.video.schemas import RecordingOut
from server.video.service import recorded_segments


async def create_run(
    runs: RunRepository,
    assets: AssetRepository,
    *,
    mission_id: uuid.UUID,
    uav_id: uuid.UUID,
    base_id: uuid.UUID,
    created_by: str | None,
    schedule_id: uuid.UUID | None = None,
    scheduled_for: datetime | None = None,
) -> Run:
    """A pending run, after checking its parts belong together and are free."""
    from server.missions.models import Mission
    from server.missions.repository import MissionRepository

    mission: Mission = await MissionRepository(runs.db, runs.principal).get(mission_id)
    uav, base = await assets.get(uav_id), await assets.get(base_id)
    if uav.kind != AssetKind.uav:
        raise Unprocessable(f"asset {uav.name} is not a UAV", code="invalid_run")
    if base.kind != AssetKind.landing_base:
        raise Unprocessable(f"asset {base.name} is not a landing base", code="invalid_run")
    if uav.base_id is not None and uav.base_id != base.id:
        raise Unprocessable(
            f"{uav.name} lives in another base; bind it to {base.name} first", code="invalid_run"
        )
    if not mission.items:
        raise Unprocessable(f"mission {mission.name} has no items", code="invalid_run")
    refusal = out_of_reach(mission, uav, base)
    if refusal is not None:
        raise refusal
    airspace = await flight_problems(runs.db, runs.principal, mission, base.id, scheduled_for)
    if airspace:
        raise refused(airspace)
    busy = await runs.busy([uav.id, base.id])
    if busy is not None:
        raise Conflict(
            f"run {busy.id} is still using {uav.name if busy.uav_id == uav.id else base.name} "
            f"(state {busy.state})",
            code="asset_busy",
        )
    now = utcnow()
    run = Run(
        organization_id=runs.principal.organization_id,
        mission_id=mission.id,
        uav_id=uav.id,
        base_id=base.id,
        schedule_id=schedule_id,
        scheduled_for=scheduled_for,
        state=State.pending.value,
        step_started_at=now,
        actions_issued=True,
        lease_until=now,
        created_by=created_by,
        created_at=now,
        updated_at=now,
    )
    runs.db.add(run)
    await runs.db.flush()
    return run


def out_of_reach(mission: Any, uav: Any, base: Any) -> Unprocessable | None:
    """The 422 for a mission the UAV cannot fly from the base and back (missions/reach.py):
    `out_of_reach` naming the item's distance and the reach, else `beyond_endurance` when the
    whole flight, legs to and from the base included, outlasts the usable endurance or range."""
    from server.missions.build import home_of
    from server.missions.items import items_of
    from server.missions.reach import base_position, check_from_base, launch_home, uav_figures

    figures = uav_figures(uav.attributes)  # a malformed attribute counts as its default here
    judged = check_from_base(
        items_of(mission.items),
        mission.speed_mps or figures.cruise_mps,
        launch_home(base.attributes, home_of(mission.home)),
        base.name if base_position(base.attributes) is not None else None,
        figures,
    )
    found = [p for p in judged.problems if p.code in ("out_of_reach", "endurance", "range")]
    if not found:
        return None
    first = found[0]
    return Unprocessable(
        first.what
        if first.code == "out_of_reach"
        else f"{first.what}: {first.value} > {first.limit}",
        code="out_of_reach" if first.code == "out_of_reach" else "beyond_endurance",
        details=[p.as_dict() for p in found],
    )


def run_out(run: Run, timeline: list[Any] | None = None) -> RunOut:
    """The API view of a run."""
    p = progress_payload(run)
    out = RunOut.model_validate(run)
    out.step, out.total_steps, out.label = p.step, p.total_steps, p.label
    out.timeline = [TransitionOut.model_validate(t) for t in timeline or []]
    return out


def _flight_time(run: Run) -> float | None:
    """Take-off to touchdown as the UAV reported them, written when the run ended."""
    return run.flight_time_s


async def report(
    runs: RunRepository, store: Any, run_id: uuid.UUID, record_dir: Path | None = None
) -> RunReport:
    """Timeline, flight track from telemetry, battery used, landing error, outcome and cause, and
    the UAV's video segments recorded during the flight (under `record_dir`)."""
    from server.telemetry.store import Query

    run, timeline = await runs.with_timeline(run_id)
    end = run.finished_at or utcnow()
    rows = await store.query(
        Query(
            run.uav_id,
            run.created_at,
            end,
            ["position.lat", "position.lon", "position.alt_rel_m", "battery.percent"],
            limit=20_000,
        )
    )
    track = [r for r in rows if "position.lat" in r]
    batteries = [
        r["battery.percent"] for r in rows if isinstance(r.get("battery.percent"), int | float)
    ]
    used = round(batteries[0] - batteries[-1], 2) if len(batteries) >= 2 else None
    landing = landing_report(*await runs.landing_events(run))
    measured = landing.agent_offset_m if landing else None
    flown = run.flight_time_s
    if flown is None and run.finished_at is None and run.flight_started_at is not None:
        flown = await runs.flight_so_far(run)
    return RunReport(
        run=run_out(run, timeline),
        flight_time_s=flown,
        battery_used_pct=used,
        landing_error_m=run.landing_error_m if run.landing_error_m is not None else measured,
        landing=landing,
        track=track,
        airspace_breaches=[breach_out(e) for e in await runs.flight_events(run, "fence_breach")],
        battery_margin_at_touchdown_pct=await _touchdown_margin(runs, run, rows, landing),
        recordings=await _recordings(run, record_dir),
    )


async def _recordings(run: Run, record_dir: Path | None) -> list[RecordingOut]:
    """The UAV's segments overlapping take-off to landing (to now while it flies), oldest first."""
    if record_dir is None or run.flight_started_at is None:
        return []
    end = run.flight_ended_at or run.finished_at or utcnow()
    found = await asyncio.to_thread(
        recorded_segments, record_dir, run.uav_id, run.flight_started_at, end
    )
    return found[::-1]


async def _touchdown_margin(
    runs: RunRepository, run: Run, rows: list[dict[str, Any]], landing: LandingReport | None
) -> float | None:
    """The battery at touchdown (the last reading before the agent's `landed`) less the UAV's
    reserve (runs/reserve.py): what the return left to spare."""
    from server.assets.models import Asset
    from server.missions.models import Mission

    if landing is None or landing.landed_at is None:
        return None
    before = [
        r["battery.percent"]
        for r in rows
        if isinstance(r.get("battery.percent"), int | float)
        and (ts := _parsed(r.get("ts"))) is not None
        and ts <= landing.landed_at
    ]
    if not before:
        return None
    uav = await runs.db.get(Asset, run.uav_id)
    mission = await runs.db.get(Mission, run.mission_id)
    model = return_model((uav.attributes if uav else None) or {}, mission)
    return round(float(before[-1]) - model.reserve_pct, 2)


def _parsed(ts: Any) -> datetime | None:
    try:
        return datetime.fromisoformat(str(ts).replace("Z", "+00:00"))
    except ValueError:
        return None


def breach_out(event: AssetEvent) -> BreachOut:
    """A `fence_breach` event of the UAV as the report shows it."""
    d = event.data or {}
    text = {k: d.get(k) if isinstance(d.get(k), str) else None for k in ("breach_type", "mode")}
    count = d.get("breach_count")
    return BreachOut(
        at=event.ts,
        breach_type=text["breach_type"] or "BOUNDARY",
        breach_count=count if isinstance(count, int) and not isinstance(count, bool) else None,
        mode=text["mode"],
        lat=_number(d, "lat"),
        lon=_number(d, "lon"),
        alt_rel_m=_number(d, "alt_rel_m"),
    )


def _number(data: dict[str, Any], key: str) -> float | None:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def landing_report(landed: AssetEvent | None, confirmed: AssetEvent | None) -> LandingReport | None:
    """The report's landing part from the agent's `landed` and the base's `landing_confirmed`."""
    if landed is None and confirmed is None:
        return None
    agent = landed.data if landed is not None and isinstance(landed.data, dict) else {}
    base = confirmed.data if confirmed is not None and isinstance(confirmed.data, dict) else {}
    sources = agent.get("fix_sources")
    path = agent.get("landing_path")
    return LandingReport(
        agent_offset_m=_number(agent, "offset_m"),
        agent_offset_north_m=_number(agent, "offset_north_m"),
        agent_offset_east_m=_number(agent, "offset_east_m"),
        agent_fix_height_m=_number(agent, "fix_height_m"),
        agent_fix_age_s=_number(agent, "fix_age_s"),
        agent_fix_sources=sources if isinstance(sources, str) and sources else None,
        agent_landing_path=path if isinstance(path, str) and path else None,
        landed_at=landed.ts if landed is not None else None,
        base_confirmed=confirmed is not None,
        base_confirmed_at=confirmed.ts if confirmed is not None else None,
        base_mass_g=_number(base, "mass_g"),
    )


def fleet(runs_in_window: list[Run], start: datetime, end: datetime) -> FleetReport:
    """The fleet summary of a window (pure): only `completed` is a success; every other finished
    run is counted by its outcome and cause."""
    ended = [
        (r, RunOutcome(r.outcome))
        for r in runs_in_window
        if r.state in {s.value for s in FINAL} and r.outcome
    ]
    outcome = Counter(o.value for _, o in ended)
    rest = [(r, o) for r, o in ended if o != RunOutcome.completed]
    causes = Counter(r.cause or "unknown" for r, _ in rest)
    by_outcome: dict[RunOutcome, dict[str, int]] = {}
    for r, o in rest:
        counts = by_outcome.setdefault(o, {})
        counts[r.cause or "unknown"] = counts.get(r.cause or "unknown", 0) + 1
    finished = len(ended)
    per: dict[uuid.UUID, dict[str, Any]] = defaultdict(
        lambda: {"runs": 0, "completed": 0, "flight": 0.0}
    )
    times = []
    for r in runs_in_window:
        ft = _flight_time(r) or 0.0
        for asset_id in (r.uav_id, r.base_id):
            per[asset_id]["runs"] += 1
            per[asset_id]["completed"] += r.outcome == "completed"
            per[asset_id]["flight"] += ft
        if r.flight_time_s is not None and r.state in {s.value for s in FINAL}:
            times.append(ft)
    return FleetReport(
        start=start,
        end=end,
        runs=len(runs_in_window),
        completed=outcome.get("completed", 0),
        completed_with_issues=outcome.get("completed_with_issues", 0),
        incomplete=outcome.get("incomplete", 0),
        aborted=outcome.get("aborted", 0),
        failed=outcome.get("failed", 0),
        in_progress=len(runs_in_window) - finished,
        success_rate=round(outcome.get("completed", 0) / finished, 4) if finished else None,
        by_outcome=by_outcome,
        failures_by_cause=dict(causes),
        mean_flight_time_s=sum(times) / len(times) if times else None,
        per_asset=[
            AssetSummary(
                asset_id=k, runs=v["runs"], completed=v["completed"], flight_time_s=v["flight"]
            )
            for k, v in per.items()
        ],
    )


class RunService(Service):
    """Runs of the caller's organisation as the API sees them: start, read, abort, report."""

    def __init__(self, uow: UnitOfWork, principal: Principal) -> None:
        super().__init__(uow, principal)
        self.repo = RunRepository(self.db, principal)

    async def create(self, mission_id: uuid.UUID, uav_id: uuid.UUID, base_id: uuid.UUID) -> Run:
        """Start an autonomous run now (the engine checks availability first)."""
        return await create_run(
            self.repo,
            AssetRepository(self.db, self.principal),
            mission_id=mission_id,
            uav_id=uav_id,
            base_id=base_id,
            created_by=self.principal.actor_id,
        )

    async def list_runs(
        self,
        page: Page,
        state: State | None,
        uav_id: uuid.UUID | None,
        outcome: RunOutcome | None = None,
    ) -> Paged[Run]:
        """Runs of the caller's organisation, newest first."""
        return await self.repo.filtered(
            page, state.value if state else None, uav_id, outcome.value if outcome else None
        )

    async def with_timeline(self, run_id: uuid.UUID) -> RunOut:
        """A run with its timeline."""
        return run_out(*await self.repo.with_timeline(run_id))

    async def abort(self, run_id: uuid.UUID, reason: str | None) -> Run:
        """Ask the run to stop safely (the engine acts on it)."""
        run = await self.repo.get(run_id)
        if State(run.state) in FINAL:
            raise Conflict(f"run {run.id} has already ended ({run.state})", code="run_finished")
        run.abort_requested = True
        run.abort_reason = reason or f"requested by {self.principal.label}"
        run.updated_at = utcnow()
        await self.db.flush()
        return run

    async def report(
        self, run_id: uuid.UUID, store: Any, record_dir: Path | None = None
    ) -> RunReport:
        """The flight history of a run (with its video segments recorded under `record_dir`)."""
        return await report(self.repo, store, run_id, record_dir)

    async def fleet(self, start: datetime | None, end: datetime | None) -> FleetReport:
        """Runs in [start, end) (default: the last 30 days), summed up."""
        end = end or utcnow()
        try:
            start = start or end - timedelta(days=30)
        except OverflowError as err:
            raise Unprocessable(
                "end is too early for the default 30-day window; give start"
            ) from err
        if start.tzinfo is None or end.tzinfo is None or start >= end:
            raise Unprocessable("start and end need a time zone and start must be before end")
        return fleet(await self.repo.in_window(start, end), start, end)
