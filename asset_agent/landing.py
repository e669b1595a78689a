"""Precision landing in the daemon: while the autopilot lands, the camera's frames, the IR beacon's
readings and the autopilot's state feed a `PrecisionLandingLoop`, whose LANDING_TARGET fields go
to the autopilot (ArduPilot PLND_TYPE=1 style, MAV_FRAME_BODY_FRD) at the configured rate.

Active while the autopilot reports it is landing (EXTENDED_SYS_STATE landed_state LANDING — LAND
mode, RTL's or a mission's final descent — or mode LAND) below `activation_height_m`. The camera is
streamed only then (a frame server renders only for subscribers); the IR sensor is subscribed all
along. Every source is optional and may be unreachable: then nothing is sent and the autopilot
lands on GNSS alone.

One clock: frames and IR readings carry capture timestamps on the sensors' clock (in the
simulator, the world clock). `SensorClock` follows that clock from the timestamps it receives
(offset and rate against the agent's monotonic clock), and stamps the autopilot's states with it,
so fusion, the Kalman filter and the control step all run in sensor-clock seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from asset_agent.config import PreclandSection
from asset_agent.precland.config import SOURCES, FaultConfig
from asset_agent.precland.loop import PrecisionLandingLoop
from asset_agent.precland.pipeline import Tick, VehicleState
from asset_agent.precland.transport import IrReceiver, frames_forever
from assetlink.dispatch import CommandRequest, result
from asynckit.tasks import cancel_and_wait
from protocol.messages import CommandResultPayload
from protocol.vocabulary import PreclandFault

log = logging.getLogger(__name__)

EARTH_RADIUS_M = 6_378_137.0
ATTITUDE, LOCAL_POSITION_NED, EXTENDED_SYS_STATE = 30, 32, 245


class SensorClock:
    """The sensors' clock as seen from here: rate and offset against `wall` from received stamps.

    now() = rate * wall + offset, with the rate fitted over the last `window_s` wall seconds (or
    fixed) and the offset the largest seen (the least-delayed sample); never goes backwards.
    """

    def __init__(
        self,
        rate: float | None = None,
        window_s: float = 2.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fixed_rate = rate
        self.window_s = window_s
        self.wall = wall
        self._samples: deque[tuple[float, float]] = deque()
        self._last = -math.inf

    @property
    def ready(self) -> bool:
        """True once a timestamp has been seen."""
        return bool(self._samples)

    @property
    def rate(self) -> float:
        """Sensor seconds per wall second."""
        if self.fixed_rate is not None:
            return self.fixed_rate
        s = self._samples
        if len(s) < 3 or s[-1][0] - s[0][0] < 0.3:
            return 1.0 if len(s) < 2 or s[-1][0] == s[0][0] else self._slope()
        return self._slope()

    def _slope(self) -> float:
        n = len(self._samples)
        mw = sum(w for w, _ in self._samples) / n
        mt = sum(t for _, t in self._samples) / n
        var = sum((w - mw) ** 2 for w, _ in self._samples)
        if var <= 0:
            return 1.0
        slope = sum((w - mw) * (t - mt) for w, t in self._samples) / var
        return slope if slope > 0 else 1.0

    def observe(self, ts: float) -> None:
        """A capture timestamp just received."""
        w = self.wall()
        self._samples.append((w, ts))
        while self._samples and w - self._samples[0][0] > self.window_s:
            self._samples.popleft()

    def now(self) -> float:
        """Current sensor-clock time (0.0 before any timestamp)."""
        if not self._samples:
            return 0.0
        r = self.rate
        offset = max(t - r * w for w, t in self._samples)
        self._last = max(self._last, r * self.wall() + offset)
        return self._last

    async def sleep(self, seconds: float) -> None:
        """Sleep this many sensor-clock seconds."""
        await asyncio.sleep(max(0.0, seconds) / self.rate)


@dataclass
class LandingStats:
    """What precision landing did, for logs and tests."""

    landings: int = 0  # times the loop was started
    frames: int = 0
    ir_readings: int = 0
    targets_sent: int = 0
    first_sent_t: float | None = None  # sensor clock
    last_sent_t: float | None = None

    @property
    def target_rate_hz(self) -> float | None:
        """LANDING_TARGET messages per sensor-clock second over the span they were sent."""
        if self.first_sent_t is None or self.last_sent_t is None:
            return None
        span = self.last_sent_t - self.first_sent_t
        return (self.targets_sent - 1) / span if span > 0 else None


def pad_offset_ned(lat: float, lon: float, pad_lat: float, pad_lon: float) -> tuple[float, float]:
    """(north, east) metres from (lat, lon) to the pad, flat-earth (fine over a landing)."""
    dn = math.radians(pad_lat - lat) * EARTH_RADIUS_M
    de = math.radians(pad_lon - lon) * EARTH_RADIUS_M * math.cos(math.radians(lat))
    return dn, de


def landing_now(state: Any, activation_height_m: float) -> bool:
    """True when the autopilot is landing (LAND, or any final descent) below the activation height."""
    landing = state.landed_state == "LANDING" or (state.mode == "LAND" and state.in_air)
    return bool(
        state.armed
        and landing
        and state.alt_rel is not None
        and state.alt_rel <= activation_height_m
    )


class PrecisionLander:
    """Runs precision landing for one autopilot; `run(stop)` is the daemon's task."""

    def __init__(self, autopilot: Any, section: PreclandSection) -> None:
        self.autopilot = autopilot
        self.section = section
        self.config = section.pipeline()
        self.clock = SensorClock(section.clock_rate)
        self.faults: dict[str, FaultConfig] = dict(self.config.faults)
        self.stats = LandingStats()
        self.loop: PrecisionLandingLoop | None = None
        self._loop_task: asyncio.Task[None] | None = None
        self._camera_task: asyncio.Task[None] | None = None
        self._position: tuple[float, float, float] | None = None
        self._velocity: tuple[float, float, float] | None = None
        self._attitude: tuple[float, float, float] | None = None
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
            await self._stop_loop()
            await cancel_and_wait([self._camera_task, *tasks])
            if ir is not None:
                ir.close()

    def _supervise(self) -> None:
        state = self.autopilot.state
        descending = state.armed and (
            state.landed_state == "LANDING" or (state.mode == "LAND" and state.in_air)
        )
        if descending and self.section.camera_port is not None and self._camera_task is None:
            self._camera_task = asyncio.create_task(self._camera(), name="precland-camera")
        elif not descending and self._camera_task is not None:
            self._camera_task.cancel()
            self._camera_task = None
        active = landing_now(state, self.section.activation_height_m)
        if active and self._loop_task is None and self.clock.ready and self._position is not None:
            self._start_loop(state)
        elif not active and self._loop_task is not None:
            self._loop_task.cancel()
            self._loop_task = self.loop = None
            log.info("precland: inactive (%d LANDING_TARGET sent)", self.stats.targets_sent)

    def _start_loop(self, state: Any) -> None:
        config = self.config.model_copy(update={"faults": dict(self.faults)})
        loop = PrecisionLandingLoop(
            config, on_tick=self._on_tick, now_fn=self.clock.now, sleep_fn=self.clock.sleep
        )
        prior = self._pad_prior(state)
        if prior is not None:
            loop.pipeline.set_pad_prior(prior, self.section.pad_sigma_m)
        now = self.clock.now()
        for source, fault in self.faults.items():
            loop.pipeline.set_fault(source, fault, now)
        self.loop = loop
        self._loop_task = asyncio.create_task(loop.run(), name="precland-loop")
        self.stats.landings += 1
        log.info("precland: active at %.1f m (pad prior %s)", state.alt_rel or 0.0, prior)

    async def _stop_loop(self) -> None:
        task, self._loop_task, self.loop = self._loop_task, None, None
        if task is not None:
            await cancel_and_wait([task])
            log.info("precland: inactive (%d LANDING_TARGET sent)", self.stats.targets_sent)

    def _pad_prior(self, state: Any) -> tuple[float, float, float] | None:
        """Pad minus vehicle (NED, camera height as down) from the surveyed pad and the GNSS position."""
        s = self.section
        if s.pad_source == "surveyed" and s.pad_lat is not None and s.pad_lon is not None:
            pad = (s.pad_lat, s.pad_lon)
        elif state.home_lat is not None and state.home_lon is not None:
            pad = (state.home_lat, state.home_lon)
        else:
            return None
        if state.lat is None or state.lon is None or state.alt_rel is None:
            return None
        dn, de = pad_offset_ned(state.lat, state.lon, *pad)
        return dn, de, state.alt_rel + self.config.control.touchdown_height

    def _on_tick(self, tick: Tick) -> None:
        lt = tick.landing_target
        if lt is None:
            return
        self.autopilot.send_landing_target(
            lt.angle_x, lt.angle_y, lt.distance, lt.frame, (lt.x, lt.y, lt.z)
        )
        st = self.stats
        st.targets_sent += 1
        st.last_sent_t = tick.t
        if st.first_sent_t is None:
            st.first_sent_t = tick.t

    # -- inputs --------------------------------------------------------------------------------

    async def _camera(self) -> None:
        async for frame in frames_forever(self.section.camera_host, self.section.camera_port or 0):
            self.clock.observe(frame.capture_ts)
            self.stats.frames += 1
            if self.loop is not None:
                self.loop.frame(frame)

    async def _ir(self, ir: IrReceiver) -> None:
        async for reading in ir.readings():
            self.clock.observe(reading.capture_ts)
            self.stats.ir_readings += 1
            if self.loop is not None:
                self.loop.ir(reading)

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
                        self.loop.vehicle(
                            VehicleState(t, self._position, self._attitude, self._velocity)
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
