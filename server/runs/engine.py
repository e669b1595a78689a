"""Drives runs: leases them, observes their assets, persists each transition, then acts on it.

Every replica runs the same loop; a run is leased by one process at a time (row lock with
SKIP LOCKED on PostgreSQL, serialised writes on SQLite), so a restarted or extra server simply
picks up where the table says a run stands.
"""

from __future__ import annotations

import logging
import uuid
from datetime import datetime, timedelta
from typing import Any

import structlog
from pydantic import ValidationError

from protocol.messages import RunProgress
from protocol.vocabulary import (
    COMMANDS,
    CheckAvailability,
    CommandParams,
    MissionItem,
    UploadMission,
)
from server.assets.models import Asset
from server.commands import service as commands
from server.kit.periodic import Periodic
from server.kit.principal import Principal, Role
from server.kit.time import utcnow
from server.realtime.channels import asset_channel, command_channel
from server.runs import repository as repo
from server.runs.energy import return_reach
from server.runs.machine import (
    FINAL,
    STEPS,
    Action,
    CommandOutcome,
    Observations,
    State,
    Transition,
    advance,
)
from server.runs.models import Run, RunStepCommand
from server.runs.outcome import Flight, Verdict, judge
from server.runs.progress import observe_transition, progress_payload
from server.runs.settle import settle
from server.services import Services

log = logging.getLogger(__name__)
LEASE_S = 8.0  # a dead holder's runs are taken over within 8 s (+ one tick)


class RunEngine:
    """The per-process loop that advances every run it holds the lease of."""

    def __init__(
        self, services: Services, node: str, tick_s: float = 0.25, idle_tick_s: float = 1.0
    ) -> None:
        """Drive runs with `services` (sessionmaker, broker, telemetry store, settings): every
        `tick_s` while this process holds runs, every `idle_tick_s` while it holds none (a new
        run starts within a second, a dead replica's run is taken over within LEASE_S + 1 s;
        four idle claims a second cost ~1.5 % of a core for nothing)."""
        self.services = services
        self.settings = services.settings
        self.node = f"runs-{node}"
        self._periodic = Periodic("run-engine", self.tick, tick_s, idle_s=idle_tick_s)

    def start(self) -> None:
        """Start the loop."""
        self._periodic.start()

    async def stop(self) -> None:
        """Stop the loop and hand the leases back, so another replica drives these runs at once
        (a process that dies without stopping leaves them to expire after LEASE_S)."""
        await self._periodic.stop()
        try:
            async with self.services.sessionmaker() as db:
                await repo.release(db, self.node, utcnow())
                await db.commit()
        except Exception:  # the database may be what is going away
            log.warning("could not hand back the run leases of %s", self.node, exc_info=True)

    def timeout_s(self, state: State) -> float:
        """The configured time budget of a step."""
        return float(self.settings.run_timeouts.get(state.value, STEPS[state].default_timeout_s))

    async def tick(self) -> bool:
        """Lease runs, then drive each one step; False when there was none to lease."""
        now = utcnow()
        async with self.services.sessionmaker() as db:
            ids = await repo.claim(db, self.node, now, now + timedelta(seconds=LEASE_S))
            await db.commit()
        for run_id in ids:
            try:
                await self.drive(run_id)
            except Exception:
                log.exception("driving run %s failed", run_id)
        return bool(ids)

    async def drive(self, run_id: uuid.UUID) -> None:
        """Issue the current step's commands if not yet out, else look and maybe transition."""
        with structlog.contextvars.bound_contextvars(run_id=str(run_id)):
            await self._drive(run_id)

    async def _drive(self, run_id: uuid.UUID) -> None:
        async with self.services.sessionmaker() as db:
            run = await repo.lock(db, run_id)
            if run is None or run.lease_owner != self.node:
                return
            if not run.actions_issued:
                nudges = await self._issue(db, run)
                await db.commit()
                for asset_id in nudges:
                    await self.services.broker.publish(
                        command_channel(asset_id), {"run_id": str(run.id)}
                    )
                return
            if State(run.state) in FINAL:
                if not await self._settle(db, run):
                    return
                await db.commit()
            else:
                obs = await self._observe(db, run)
                noted = self._abort_noted(db, run)
                if noted:
                    await db.commit()
                transition = advance(State(run.state), obs, aborting=run.aborting)
                if transition is None:
                    if noted:  # operators see the abort taken at once, not at the next step
                        await self._publish(run)
                    return
                previous, entered = run.state, run.step_started_at
                verdict = None
                if transition.to in FINAL:
                    verdict = judge(transition, await self._flight(db, run), _charging(obs))
                    transition = verdict.transition
                # written first: a server that dies right after this resumes in the new step
                await self._record(db, run, transition, verdict)
                await db.commit()
                observe_transition(previous, entered, run)
                log.info(
                    "run %s: %s -> %s: %s",
                    run.id,
                    previous,
                    transition.to.value,
                    transition.reason,
                )
        await self._publish(run)

    async def _settle(self, db: Any, run: Run) -> bool:
        """A final run's safe commands (the close on the way out) have ended: say what happened
        (settle.py), alert when the base was not made safe, and stop watching. True if recorded."""
        rows = await repo.step_commands(db, run.id)
        if not rows:
            return False
        outcomes = await self._outcomes(db, rows)
        settled = settle(run.reason, outcomes) if len(outcomes) == len(rows) else None
        if settled is None:
            return False
        now = utcnow()
        repo.note(db, run, run.state, settled.note, settled.cause, now)
        run.reason, run.alert, run.updated_at = settled.reason, run.alert or settled.alert, now
        await repo.replace_step_commands(db, run.id, [])
        log.log(
            logging.WARNING if settled.alert else logging.INFO,
            "run %s (%s): %s",
            run.id,
            run.state,
            settled.note,
        )
        return True

    def _abort_noted(self, db: Any, run: Run) -> bool:
        """An abort asked for in a step that has no abort exit (the UAV is already landing or
        back): noted in the timeline where it was asked (so the console shows it there, not at
        the step the run ends in), and carried out as an aborting run. True if noted."""
        state = State(run.state)
        if not run.abort_requested or run.aborting or state in FINAL or STEPS[state].abort:
            return False
        why = f"aborted by an operator: {run.abort_reason}" if run.abort_reason else "aborted"
        repo.note(
            db, run, run.state, f"{why}; the run finishes {STEPS[state].label.lower()} first",
            "operator_abort", utcnow(),
        )  # fmt: skip
        run.aborting = True
        return True

    async def _flight(self, db: Any, run: Run) -> Flight:
        """What the UAV reported of its flight and how the run's flying step ended."""
        if run.flight_started_at is None:
            return Flight()
        names = await repo.event_names_since(db, run.uav_id, run.flight_started_at)
        return Flight(
            mission_finished="mission_finished" in names,
            returned=await repo.flying_exit_cause(db, run.id),
            operator_return=await repo.operator_returned(db, run.uav_id, run.flight_started_at),
            landed_without_precision="landed_without_precision" in names,
        )

    async def _record(
        self, db: Any, run: Run, transition: Transition, verdict: Verdict | None = None
    ) -> None:
        """The transition in the timeline, the run in its new step, the step's commands pending;
        a final one with its verdict (outcome.py) and the flight time the UAV reported."""
        now = utcnow()
        repo.note(db, run, transition.to.value, transition.reason, transition.cause, now)
        if transition.cause == "operator_abort":
            run.aborting = True
        if run.state == State.flying.value:
            run.flight_ended_at = now
        if transition.to == State.flying:
            run.flight_started_at = now
        run.state, run.step_started_at, run.updated_at = transition.to.value, now, now
        run.reason = transition.reason
        run.alert = run.alert or transition.alert
        pending = [*transition.extra_actions, *STEPS[transition.to].actions]
        await repo.replace_step_commands(db, run.id, pending)
        run.actions_issued = not pending
        if transition.to in FINAL:
            run.finished_at = now
            run.outcome = verdict.outcome.value if verdict else transition.to.value
            run.cause = verdict.cause if verdict else transition.cause or None
            run.issues = [i.value for i in verdict.issues] if verdict else []
            if run.flight_started_at is not None:
                run.flight_time_s = await repo.reported_flight_s(
                    db, run.uav_id, run.flight_started_at
                )

    async def _publish(self, run: Run) -> None:
        message = RunProgress(payload=progress_payload(run)).model_dump(mode="json")
        for asset_id in {run.uav_id, run.base_id}:
            await self.services.broker.publish(asset_channel(asset_id), message)

    async def _issue(self, db: Any, run: Run) -> set[uuid.UUID]:
        """Create the step's pending commands; the assets to nudge."""
        state = State(run.state)
        rows = await repo.step_commands(db, run.id)
        if not rows:  # a step entered before its commands were recorded: the table's own
            rows = await repo.replace_step_commands(db, run.id, STEPS[state].actions)
        timeout = self.timeout_s(state) if state not in FINAL else 120.0
        nudges: set[uuid.UUID] = set()
        for row in rows:
            if row.command_id is not None:
                continue
            # rows are written from Actions only, so a target is "uav" or "base"
            action = Action("uav" if row.target == "uav" else "base", COMMANDS[row.command])
            asset_id = run.uav_id if action.target == "uav" else run.base_id
            cmd = await commands.create(
                db,
                organization_id=run.organization_id,
                asset_id=asset_id,
                command=await self._command(db, run, action),
                timeout_s=timeout,
                created_by=f"run:{run.id}",
            )
            row.command_id = cmd.id
            nudges.add(asset_id)
        run.actions_issued = True
        return nudges

    async def _command(self, db: Any, run: Run, action: Action) -> CommandParams:
        """The typed command of an action, its params filled in from the run."""
        if action.command is UploadMission:
            from server.missions.build import flight_items
            from server.missions.models import Mission

            mission = await db.get(Mission, run.mission_id)
            dicts = flight_items(mission.items, mission.speed_mps) if mission else []
            items = [MissionItem.model_validate(i) for i in dicts]
            fence = await self._fence(db, run, mission) if mission else None
            if fence is None:
                return UploadMission(mission_id=run.mission_id, items=tuple(items))
            return UploadMission(
                mission_id=run.mission_id,
                items=tuple(items),
                fence=tuple(MissionItem.model_validate(i) for i in fence.items),
                rally=tuple(MissionItem.model_validate(i) for i in fence.rally),
                fence_alt_max_m=fence.alt_max_m,
            )
        if action.target == "base" and action.command is CheckAvailability:
            uav = await db.get(Asset, run.uav_id)
            attrs = (uav.attributes if uav else None) or {}
            weight = {k: attrs[k] for k in ("mass_g", "mass_window_g") if k in attrs}
            try:
                return CheckAvailability.model_validate(weight)
            except ValidationError:
                log.warning("run %s: the UAV's mass attributes are not numbers: %s", run.id, weight)
                return CheckAvailability()
        return action.command()

    async def _outcomes(
        self, db: Any, rows: list[RunStepCommand]
    ) -> dict[tuple[str, str], CommandOutcome]:
        found = await repo.commands_by_id(db, [r.command_id for r in rows if r.command_id])
        return {
            (row.target, row.command): CommandOutcome(cmd.status, cmd.reason, cmd.result)
            for row in rows
            if row.command_id and (cmd := found.get(row.command_id)) is not None
        }

    async def _fence(self, db: Any, run: Run, mission: Any) -> Any:
        """The fence and rally points the UAV enforces on board (server/airspace/fence.py)."""
        from server.airspace.service import flight_fence

        return await flight_fence(db, _system(run), mission, run.base_id)

    async def _airspace(self, db: Any, run: Run) -> str:
        """Why the run's mission breaks the airspace active now ("" when it does not)."""
        from server.airspace.service import flight_problems
        from server.missions.models import Mission

        mission = await db.get(Mission, run.mission_id)
        if mission is None:
            return ""
        problems = await flight_problems(db, _system(run), mission, run.base_id)
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        return f"{problems[0].what}{more}" if problems else ""

    async def _observe(self, db: Any, run: Run) -> Observations:
        outcomes = await self._outcomes(db, await repo.step_commands(db, run.id))
        since = run.step_started_at
        uav_events = await repo.event_names_since(db, run.uav_id, since)
        # the base's events since take-off: after a server restart or a cut the base's outbox may
        # replay its landing_confirmed before the run has caught up to `confirming`; it is an edge
        # (the UAV arrived on the lift), so one stored after the flight began is this landing's
        base_since = since
        if run.state == State.confirming.value and run.flight_started_at is not None:
            base_since = min(since, run.flight_started_at)
        base_events = await repo.event_names_since(db, run.base_id, base_since)
        store = self.services.telemetry
        uav = await store.latest(run.uav_id) or {}
        base = await store.latest(run.base_id) or {}
        landed = (
            uav.get("landed_state") == "on_ground"
            and uav.get("armed") is False
            and _after(uav.get("ts"), since)
        )
        airspace = await self._airspace(db, run) if run.state == State.checking.value else ""
        # in flight: the reserve's margin (flying) and whether home is in reach at all (landing)
        heading_out = run.state in (State.flying.value, State.landing.value)
        reach = await return_reach(db, run, uav, base) if heading_out else None
        return Observations(
            airspace=airspace,
            return_margin_pct=reach.margin_pct if reach is not None else None,
            home_out_of_reach=reach is not None and reach.out_of_reach,
            home_need_pct=reach.need_pct if reach is not None else None,
            battery_pct=reach.battery_pct if reach is not None else None,
            elapsed_s=(utcnow() - since).total_seconds(),
            timeout_s=self.timeout_s(State(run.state)),
            commands=outcomes,
            uav_events=uav_events,
            base_events=base_events,
            uav_landed=landed,
            base_mass_g=base.get("scale_mass_g"),
            base_confirms=base.get("landing_confirmed") is True and _after(base.get("ts"), since),
            base_heard=_after(base.get("ts"), since),
            abort_requested=run.abort_requested,
            abort_reason=run.abort_reason,
            took_off="took_off" in uav_events or "armed" in uav_events,
        )


def _charging(obs: Observations) -> CommandOutcome | None:
    return obs.commands.get(("base", "start_charging"))


def _system(run: Run) -> Principal:
    """The run's own reader of its organisation's rows (zones)."""
    return Principal(
        kind="user",
        session_id=uuid.UUID(int=0),
        organization_id=run.organization_id,
        role=Role.viewer,
        label=f"run {run.id}",
    )


def _after(ts: str | None, since: datetime) -> bool:
    if not ts:
        return False
    try:
        return datetime.fromisoformat(ts) >= since
    except ValueError:
        return False
