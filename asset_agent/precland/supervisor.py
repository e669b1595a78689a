"""Precision landing in the daemon: the supervisor that starts and stops the landing loop.

While the autopilot lands, the camera's frames, the IR beacon's readings and the autopilot's state
(with its GNSS fix type, which sets the filter's GNSS drift) feed a `PrecisionLandingLoop`
(loop.py), whose LANDING_TARGET fields go to the autopilot (ArduPilot PLND_TYPE=1 style,
MAV_FRAME_BODY_FRD) at the configured rate.

Active while the autopilot is landing (landed_state LANDING — LAND mode, RTL's or a mission's final
descent — or mode LAND) below `activation_height_m`, once the pad's position is known (surveyed,
or home: an agent just started may not have heard HOME_POSITION yet). landed_state is the
autopilot's EXTENDED_SYS_STATE, or inferred where it sends none (autopilot/flight_state.py). The
camera is streamed only then (a frame server renders only for subscribers); the IR sensor is
subscribed all along. Every source is optional and may be unreachable: then nothing is sent and
the autopilot lands on GNSS alone. When the sources run but none has seen the pad within
`[precland.search] acquire_s`, the agent takes the vehicle to search for it and applies the
fallback rule before it hands the descent back (takeover.py); an abandoned landing is reported as
a `landing_aborted` event. Restarted while the agent flew the landing itself, it hands the descent
back (resume.py). An abandoned landing holds in GUIDED at the safe height for the operator; a
failsafe the autopilot reports meanwhile hands LAND back (hold.py). The parameters a landing sets
are given back once it is over, by a restarted agent too (restore.py). The autopilot's states are
stamped with the `SensorClock` (clock.py), so the loop runs in the sensors' seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import time
from types import MappingProxyType
from typing import Any

from pydantic import ValidationError

from asset_agent.config import PreclandSection
from asset_agent.events import Event
from asset_agent.precland.clock import SensorClock
from asset_agent.precland.config import SOURCES, AutopilotDescentConfig, FaultConfig
from asset_agent.precland.hold import HoldWatch
from asset_agent.precland.loop import PrecisionLandingLoop
from asset_agent.precland.pipeline import Tick, VehicleState
from asset_agent.precland.readiness import descent_gate
from asset_agent.precland.report import LandingStats, PadFix, pad_prior
from asset_agent.precland.restore import ParamLedger
from asset_agent.precland.resume import Memory, TakeoverRecord
from asset_agent.precland.silence import SilenceWatch
from asset_agent.precland.takeover import Takeover, descending
from asset_agent.precland.transport import IrReceiver, frames_forever
from assetlink.dispatch import CommandRequest, result
from asynckit.tasks import cancel_and_wait
from protocol.messages import CommandResultPayload
from protocol.vocabulary import PreclandFault

log = logging.getLogger(__name__)

ATTITUDE, LOCAL_POSITION_NED, EXTENDED_SYS_STATE = 30, 32, 245


def landing_now(state: Any, activation_height_m: float) -> bool:
    """True when the autopilot is landing (LAND, or any final descent) below the activation height."""
    return descending(state) and state.alt_rel is not None and state.alt_rel <= activation_height_m


class PrecisionLander:
    """Runs precision landing for one autopilot; `run(stop)` is the daemon's task."""

    def __init__(
        self, autopilot: Any, section: PreclandSection, memory: Memory | None = None
    ) -> None:
        """`memory`: where the agent's hold on the vehicle outlives a restart (resume.py)."""
        self.autopilot = autopilot
        self.section = section
        self.config = section.pipeline()
        self.clock = SensorClock(section.clock_rate)
        self.faults: dict[str, FaultConfig] = dict(self.config.faults)
        self.stats = LandingStats()
        self.silence = SilenceWatch()  # frames in, no target out: a warning (silence.py)
        self.loop: PrecisionLandingLoop | None = None
        self._loop_task: asyncio.Task[None] | None = None
        self._camera_task: asyncio.Task[None] | None = None
        self._position: tuple[float, float, float] | None = None
        self._velocity: tuple[float, float, float] | None = None
        self._attitude: tuple[float, float, float] | None = None
        self.last_fix: PadFix | None = None  # of the current (or last) landing
        self.takeover: Takeover | None = None  # the current (or last) landing's search
        self._takeover_task: asyncio.Task[None] | None = None
        self._gate_task: asyncio.Task[None] | None = None  # PLND_XY_DIST_MAX for this landing
        self.xy_dist_max: float | None = None  # the value the autopilot last confirmed
        self._armed = False
        self.record = TakeoverRecord(memory)
        # what a restarted agent does with the vehicle it first finds (resume.py), or a disarm
        self.first_look: asyncio.Task[None] | None = None
        # the first look, and a failsafe in the hold of an abandoned landing (hold.py)
        self.hold = HoldWatch(autopilot, self.record, self.clock.sleep)
        self.params = ParamLedger(autopilot, memory)  # what a landing changed, given back after
        self.events: list[Event] = []  # for the daemon's event stream (drained by the reporter)
        if self.config.mode != "landing_target":
            log.warning(
                "precland: only mode landing_target is wired in the daemon; nothing is sent"
            )

    # -- faults ------------------------------------------------------------------------------

    def set_fault(self, source: str, fault: FaultConfig) -> None:
        """Run-time fault injection for one source (now and for later landings)."""
        self.faults[source] = fault
        if self.loop is not None:
            self.loop.set_fault(source, fault)

    async def fault_command(self, request: CommandRequest[PreclandFault]) -> CommandResultPayload:
        """`precland_fault {source, r_drop, p_keep, p_drop, below_m, above_m}`; source "marker"
        means pattern and ArUco."""
        p = request.command
        source = p.source
        targets = ("pattern", "aruco") if source == "marker" else (source,)
        if not all(s in SOURCES for s in targets):
            return result(
                "rejected", f"unknown source {source!r}: one of {', '.join(SOURCES)}, marker"
            )
        try:
            fault = FaultConfig(
                r_drop=p.r_drop or 0.0,
                p_keep=p.p_keep or 0.0,
                p_drop=p.p_drop or 0.0,
                fail_below_m=p.below_m,
                fail_above_m=p.above_m,
            )
        except ValidationError as err:
            return result("rejected", f"bad fault: {err.errors()[0]['msg']}")
        for s in targets:
            self.set_fault(s, fault)
        return result("succeeded", f"precland fault on {source}: {fault.model_dump()}")

    # -- running -------------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        """Watch the autopilot; run the landing loop while it lands. Never raises but cancel."""
        try:
            await self.record.load()
            await self.params.load()
        except Exception:  # the state file is the link's: it says why it failed
            log.exception("precland: what the previous agent kept could not be read")
        tasks = [asyncio.create_task(self._states(), name="precland-states")]
        ir: IrReceiver | None = None
        ir_port = self.section.ir_port  # the receiver exists only when a port is configured
        if ir_port is not None:
            ir = IrReceiver()
            try:
                await ir.start()
                tasks.append(asyncio.create_task(self._ir(ir), name="precland-ir"))
            except OSError as err:
                log.warning("precland: IR receiver not started: %s", err)
                ir = None
        try:
            next_subscribe = 0.0
            while not stop.is_set():
                try:
                    if (
                        ir is not None
                        and ir_port is not None
                        and time.monotonic() >= next_subscribe
                    ):
                        ir.subscribe(self.section.ir_host, ir_port)
                        next_subscribe = time.monotonic() + 1.0
                    self._supervise()
                except Exception:
                    log.exception("precland supervision failed")
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), 0.05)
        finally:
            # cancelled while stopping (the daemon's own stop), the landing's tasks still end:
            # a takeover left behind would fly on with a closed link
            await asyncio.shield(self._close(tasks, ir))

    async def _close(self, tasks: list[asyncio.Task[None]], ir: IrReceiver | None) -> None:
        await self._stop_loop()
        await cancel_and_wait([self._camera_task, self.first_look, *tasks])
        await self.hold.close()
        await self.params.close()
        if ir is not None:
            ir.close()

    def _supervise(self) -> None:
        state = self.autopilot.state
        taken = self.takeover is not None and self.takeover.active  # the agent searches
        if state.armed and not self._armed:
            self.takeover = None  # a new flight searches afresh
        # where the pad is, from the survey or home: without it a search or a fallback would
        # centre on nothing (an agent just started has not heard HOME_POSITION yet)
        prior = pad_prior(self.section, state, self.config.control.touchdown_height)
        decision = self.record.first_sight(state) if prior is not None else None
        disarmed = self._armed and not state.armed and self.record.current is not None
        if decision is not None or disarmed:
            self.first_look = asyncio.create_task(self.hold.act_on_first_sight(decision or "none"))
        self._armed = bool(state.armed)
        self.hold.check(state, taken)
        warning = self.silence.check(self.clock.epochs, taken)
        if warning is not None:
            log.warning(
                "precland: no LANDING_TARGET sent while readings arrive: %s", warning.detail
            )
            self.events.append(warning)
        lands = descending(state) or taken
        if lands and self.section.camera_port is not None and self._camera_task is None:
            self._camera_task = asyncio.create_task(self._camera(), name="precland-camera")
        elif not lands and self._camera_task is not None:
            self._camera_task.cancel()
            self._camera_task = None
        active = landing_now(state, self.section.activation_height_m) or taken
        # not before the predecessor's landing is handed back (`act_on_first_sight`): its LAND,
        # answered after this landing's takeover began, would be told to it as another's mode
        # change
        resumed = self.first_look is None or self.first_look.done()
        if active and self._loop_task is None and self.ready and prior is not None and resumed:
            self._start_loop(state, prior)
        elif not active and self._loop_task is not None:
            self._loop_task.cancel()
            for task in (self._takeover_task, self._gate_task):
                if task is not None:
                    task.cancel()
            self._loop_task = self.loop = self._takeover_task = self._gate_task = None
            self.silence.stop()
            log.info("precland: inactive (%d LANDING_TARGET sent)", self.stats.targets_sent)
        undecided = self.record.left is not None and self.record.decision is None  # restore.py
        self.params.check(state, self._loop_task is not None or lands or not resumed or undecided)

    @property
    def ready(self) -> bool:
        """The sensors' clock has a timestamp and the autopilot's position is known: a landing
        loop can start (once the pad's position is known too)."""
        return self.clock.ready and self._position is not None

    def _start_loop(self, state: Any, prior: tuple[float, float, float]) -> None:
        config = self.config.model_copy(update={"faults": dict(self.faults)})
        loop = PrecisionLandingLoop(  # a camera frame that saw the pad: a reading (silence.py)
            config, self._on_tick, self.silence.detections, self.clock.now, self.clock.sleep
        )
        loop.pipeline.set_pad_prior(prior, self.section.pad_sigma_m)
        now = self.clock.now()
        for source, fault in self.faults.items():
            loop.pipeline.set_fault(source, fault, now)
        self.loop = loop
        self.last_fix = None
        self._loop_task = asyncio.create_task(loop.run(), name="precland-loop")
        # the search once per flight, unless it was abandoned; the guard every landing loop
        path = self.takeover.path if self.takeover is not None else None
        path = None if path == "aborted-climb" else path
        self.takeover = Takeover(
            self.autopilot,
            loop.pipeline,
            config,
            self.clock.now,
            self.clock.sleep,
            path,
            self.record.keep,
        )
        self._takeover_task = asyncio.create_task(self._take_over(self.takeover))
        if config.mode == "landing_target" and config.autopilot.xy_dist_max_m is not None:
            self._gate_task = asyncio.create_task(self._descent_gate(config.autopilot))
        self.stats.landings += 1
        self.silence.start()
        log.info("precland: active at %.1f m (pad prior %s)", state.alt_rel or 0.0, prior)

    async def _take_over(self, takeover: Takeover) -> None:
        try:
            await takeover.run()
        except Exception:  # a refused mode change: the autopilot keeps its own landing
            log.exception("precland: the search or the guard failed")
            return
        if takeover.path == "aborted-climb":
            detail: dict[str, Any] = {
                "landing_path": "aborted-climb",
                "reason": takeover.abort_reason or "pad not found, no RTK fix",
            }
            if takeover.losses:  # the guard took it: lost too high or off the pad
                detail["lost_at_m"] = takeover.losses[-1]
            self.events.append(Event("landing_aborted", MappingProxyType(detail)))

    async def _descent_gate(self, cfg: AutopilotDescentConfig) -> None:
        """PLND_XY_DIST_MAX for this landing (readiness.py), the confirmed value kept."""
        ap, now, sleep = self.autopilot, self.clock.now, self.clock.sleep
        await descent_gate(ap, self.params, cfg, now, sleep, self._confirmed)

    def _confirmed(self, value: float) -> None:
        self.xy_dist_max = value

    def drain_events(self) -> list[Event]:
        """The events precision landing raised since the last call."""
        out, self.events = self.events, []
        return out

    async def _stop_loop(self) -> None:
        await cancel_and_wait([self._takeover_task, self._gate_task])
        task, self._loop_task, self.loop = self._loop_task, None, None
        self.silence.stop()
        if task is not None:
            await cancel_and_wait([task])
            log.info("precland: inactive (%d LANDING_TARGET sent)", self.stats.targets_sent)

    def touchdown_offset(self) -> dict[str, Any]:
        """What the agent knows of where it touched down: its last measured fix of the pad, and
        the landing's path: "search-then-precision" or "rtk-fallback" after a search (takeover.py),
        else "precision" with a fix, "gnss" without (the sources never ran: the autopilot landed
        on GNSS alone)."""
        path = self.takeover.path if self.takeover is not None else None
        if path not in ("search-then-precision", "rtk-fallback"):
            path = "precision" if self.last_fix is not None else "gnss"
        # what the landing loop saw and sent: frames with no target is a landing the camera
        # watched and did not steer (the server alerts on it)
        seen = self.silence.landed_detail() if self.stats.landings else {}
        if self.last_fix is None:  # landed on GNSS alone: nothing was measured
            return {"offset_source": "none", "landing_path": path, **seen}
        fix = self.last_fix.touchdown(self.clock.now())
        return {"offset_source": "precland", "landing_path": path, **fix, **seen}

    def with_touchdown(self, event: Event) -> Event:
        """The `landed` event with the measured touchdown offset in its data."""
        return Event(event.kind, MappingProxyType({**event.detail, **self.touchdown_offset()}))

    def _on_tick(self, tick: Tick) -> None:
        target = tick.target
        if target is not None and target.kind != "held" and target.sources:
            self.last_fix = PadFix(tick.t, target.rel_ned, target.sources)
            self.stats.measured += 1
        lt = tick.landing_target
        if lt is None:
            return
        self.autopilot.send_landing_target(
            lt.angle_x, lt.angle_y, lt.distance, lt.frame, (lt.x, lt.y, lt.z)
        )
        self.silence.sent()
        st = self.stats
        st.targets_sent += 1
        st.last_sent_t = tick.t
        if st.first_sent_t is None:
            st.first_sent_t = tick.t

    # -- inputs --------------------------------------------------------------------------------

    async def _camera(self) -> None:
        async for frame in frames_forever(self.section.camera_host, self.section.camera_port or 0):
            # on the agent's time base across the camera clock's restarts (clock.py)
            t = self.clock.observe(frame.capture_ts, "camera")
            self.stats.frames += 1
            if self.loop is not None:
                self.loop.frame(dataclasses.replace(frame, capture_ts=t))

    async def _ir(self, ir: IrReceiver) -> None:
        async for reading in ir.readings():
            t = self.clock.observe(reading.capture_ts, "ir")
            self.stats.ir_readings += 1
            self.silence.reading("ir", reading.detected)
            if self.loop is not None:
                self.loop.ir(dataclasses.replace(reading, capture_ts=t))

    async def _states(self) -> None:
        wanted = (ATTITUDE, LOCAL_POSITION_NED)
        with self.autopilot.tap(lambda m: m.get_msgId() in wanted) as queue:
            while True:
                msg = await queue.get()
                try:
                    if msg.get_msgId() == ATTITUDE:
                        self._attitude = (msg.roll, msg.pitch, msg.yaw)
                    else:
                        self._position = (msg.x, msg.y, msg.z)
                        self._velocity = (msg.vx, msg.vy, msg.vz)
                    if self.loop is not None and self._attitude and self._position:
                        t = self.clock.now()
                        # GPS_RAW_INT's fix type (0 before one arrives: unknown)
                        fix = getattr(self.autopilot.state, "fix_type", 0) or None
                        self.loop.vehicle(
                            VehicleState(t, self._position, self._attitude, self._velocity, fix)
                        )
                except Exception:
                    log.exception("precland: bad autopilot state skipped")


def stream_rates(section: PreclandSection) -> dict[int, float]:
    """Extra telemetry the precision landing needs from the autopilot (msg id -> Hz)."""
    return {
        ATTITUDE: section.state_rate_hz,
        LOCAL_POSITION_NED: section.state_rate_hz,
        EXTENDED_SYS_STATE: 5.0,
    }
