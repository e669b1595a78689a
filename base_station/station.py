"""The `Station` facade: the daemon's command entry point and event stream.

`execute(command)` is an async iterator of `Progress` values ending in exactly one
`Result` (succeeded / rejected / failed, with a human-readable reason); the command is one of
`protocol.vocabulary`'s models (or a `(name, params)` pair, parsed into one): Open, Close,
OpenPanels, ClosePanels, LiftUp, LiftDown, StartCharging, StopCharging, CheckAvailability,
Stop, ResetFaults. `subscribe()` streams `Event`s. These two are all a server link needs.

Safety rules enforced here: one motion at a time (a duplicate or replayed motion command
while one runs is rejected; one whose target is already reached succeeds without writing
anything); interlocks checked by the daemon before any write, with the reason; `stop` is
accepted in every state; motion fails (and is reported) on E-stop, stall, a link loss not back
within `[motion] link_wait_s`, or travel timeout. Charging and the availability check, which
move nothing, are charging.py's.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable, Mapping
from typing import Any

from pydantic import ValidationError

from base_station.base_telemetry import build_telemetry
from base_station.charging import ChargingCommands
from base_station.config import StationConfig
from base_station.coordinator import Coordinator
from base_station.devices.axis import AxisSpec, Decision, MotionTracker, Outcome
from base_station.devices.lift import LIFT, check_lift_down, check_lift_up
from base_station.devices.panels import PANELS, check_close_panels, check_open_panels
from base_station.events import Event, EventKind, Subscription
from base_station.outcomes import Item, Progress, Result, Status
from base_station.plc import (
    MOTION_BLOCKING_FAULTS,
    Coil,
    PlcLinkError,
    fault_names,
)
from protocol import vocabulary
from protocol.telemetry_payloads import LandingBaseTelemetry, Rtk
from protocol.vocabulary import (
    CheckAvailability,
    Close,
    ClosePanels,
    CommandParams,
    LiftDown,
    LiftUp,
    Open,
    OpenPanels,
    ResetFaults,
    StartCharging,
    Stop,
    StopCharging,
)

log = logging.getLogger(__name__)

CommandHandler = Callable[[Any], AsyncIterator[Item]]
MOTION_COMMANDS = ("open", "close", "open_panels", "close_panels", "lift_up", "lift_down")


class Station:
    """Commands and events of the landing base, on top of the coordinator."""

    def __init__(self, coordinator: Coordinator, config: StationConfig) -> None:
        self.coord = coordinator
        self.config = config
        self._motion: str | None = None
        self._stop_gen = 0
        self._charging = ChargingCommands(coordinator, config, self._reject, self._fail)
        self._handlers: dict[type[CommandParams], CommandHandler] = {
            Open: self._open,
            Close: self._close,
            OpenPanels: self._axis_cmd(PANELS, +1, check_open_panels),
            ClosePanels: self._axis_cmd(PANELS, -1, check_close_panels),
            LiftUp: self._axis_cmd(LIFT, +1, check_lift_up),
            LiftDown: self._axis_cmd(LIFT, -1, check_lift_down),
            StartCharging: self._charging.start,
            StopCharging: self._charging.stop,
            CheckAvailability: self._charging.check_availability,
            Stop: self._stop,
            ResetFaults: self._reset_faults,
        }

    @property
    def commands(self) -> tuple[type[CommandParams], ...]:
        """The command types `execute` accepts."""
        return tuple(self._handlers)

    def subscribe(self) -> Subscription:
        """A stream of every event (refusals, faults, link, E-stop, landing, charge, power)."""
        return self.coord.events.subscribe()

    def telemetry(self, rtk: Rtk | None = None) -> LandingBaseTelemetry:
        """The telemetry message of the latest snapshot (with the RTK receiver's state, if given)."""
        return build_telemetry(self.coord.snapshot, rtk)

    async def telemetry_stream(
        self, hz: float | None = None
    ) -> AsyncIterator[LandingBaseTelemetry]:
        """Telemetry at `hz` (default `telemetry_hz` of the configuration), forever."""
        period = 1.0 / (hz or self.config.telemetry_hz)
        while True:
            yield self.telemetry()
            await asyncio.sleep(period)

    async def execute(
        self, command: CommandParams | str, params: Mapping[str, Any] | None = None
    ) -> AsyncIterator[Item]:
        """Run one command: Progress values, then one Result. Never raises for bad input.

        `command` is a typed command, or a name whose `params` are parsed into one here.
        """
        if isinstance(command, str):
            name = command
            if params is not None and not isinstance(params, Mapping):
                yield self._reject(name, "params must be an object")
                return
            try:
                command = vocabulary.parse(name, params)
            except (vocabulary.UnknownCommand, ValidationError) as err:
                yield self._reject(name, self._refusal(name, err))
                return
        name = command.name
        handler = self._handlers.get(type(command))
        if handler is None:
            yield self._reject(name, self._refusal(name, vocabulary.UnknownCommand(name)))
            return
        exclusive = name in MOTION_COMMANDS
        if exclusive and self._motion is not None:
            yield self._reject(name, f"busy: {self._motion} in progress (send stop first)")
            return
        if exclusive:
            self._motion = name
        try:
            async for item in handler(command):
                yield item
        except PlcLinkError as err:
            yield self._fail(name, f"PLC link error: {err}")
        except Exception as err:
            log.exception("station: %s failed", name)
            yield self._fail(name, f"internal error: {err}")
        finally:
            if exclusive:
                self._motion = None

    async def run(
        self, command: CommandParams | str, params: Mapping[str, Any] | None = None
    ) -> Result:
        """Execute a command to its end and return only its Result."""
        result: Result | None = None
        async for item in self.execute(command, params):
            if isinstance(item, Result):
                result = item
        assert result is not None
        return result

    async def shutdown(self) -> None:
        """Stop any motion this daemon started (called on a clean exit)."""
        if self._motion is not None and self.coord.snapshot.link_up:
            self._stop_gen += 1
            try:
                await self.coord.write_coil(Coil.MOTION_STOP, True)
            except PlcLinkError as err:
                log.warning("station: could not stop motion on shutdown: %s", err)

    # --- helpers -------------------------------------------------------------------------

    def _refusal(self, name: str, err: Exception) -> str:
        if isinstance(err, ValidationError):
            return f"invalid params for {name}: {vocabulary.describe(err)}"
        known = ", ".join(c.name for c in self._handlers)
        return f"unknown command {name!r}; known: {known}"

    def _reject(self, command: str, reason: str) -> Result:
        self.coord.emit(Event(EventKind.REFUSAL, reason, {"command": command}))
        return Result(command, Status.REJECTED, reason)

    def _fail(self, command: str, reason: str) -> Result:
        self.coord.emit(
            Event(
                EventKind.MOTION_FAILED if command in MOTION_COMMANDS else EventKind.REFUSAL,
                reason,
                {"command": command},
            )
        )
        return Result(command, Status.FAILED, reason)

    def _timeout(self, spec: AxisSpec) -> float:
        m = self.config.motion
        travel = m.panels_travel_s if spec is PANELS else m.lift_travel_s
        return travel * m.timeout_factor + m.timeout_margin_s

    # --- motion --------------------------------------------------------------------------

    def _axis_cmd(self, spec: AxisSpec, direction: int, check: Callable[..., Decision]):  # type: ignore[no-untyped-def]
        async def handler(command: CommandParams) -> AsyncIterator[Item]:
            """Move `spec` towards `direction`."""
            async for item in self._move(command.name, spec, direction, check):
                yield item

        return handler

    async def _move(
        self, command: str, spec: AxisSpec, direction: int, check: Callable[..., Decision]
    ) -> AsyncIterator[Item]:
        wait = self.config.motion.link_wait_s
        if not self.coord.snapshot.link_up and wait > 0:
            yield Progress(command, "plc_link", f"PLC link down: waiting up to {wait:g} s for it")
        # the link waited for, a watchdog latch alone cleared first
        snap = await self.coord.before_motion(wait)
        decision = check(snap.plc, snap.link_up)
        if not decision.allowed:
            yield self._reject(command, decision.reason)
            return
        if decision.already_there:
            yield Result(command, Status.SUCCEEDED, decision.reason)
            return
        word = spec.open_word if direction > 0 else spec.closed_word
        gen = self._stop_gen
        coil = spec.open_coil if direction > 0 else spec.close_coil
        written = await self.coord.write_coil(coil, True)
        self.coord.trackers[spec.name].commanded(direction)
        tracker = MotionTracker(spec, direction, written, self._timeout(spec))
        yield Progress(
            command,
            f"{spec.name}_moving",
            f"{spec.name} moving {word}",
            spec.read(snap.plc).position_pct if snap.plc else None,
        )
        last_pct = -100.0
        seq = snap.seq
        rode_out = False  # a link loss waited out already
        while True:
            snap = await self.coord.wait_next(seq, 1.0)
            seq = snap.seq
            if self._stop_gen != gen:
                if rode_out and snap.link_up:  # a stop sent while the link was down wrote none
                    await self.coord.write_coil(Coil.MOTION_STOP, True)
                pos = spec.read(snap.plc).position_pct if snap.plc else 0.0
                yield self._fail(command, f"stopped by operator: {spec.name} at {pos:.0f} %")
                return
            outcome, reason = tracker.update(
                snap.plc, snap.link_up, time.monotonic(), snap.read_started >= written
            )
            if outcome is Outcome.FAILED and not snap.link_up and not rode_out:
                # a blip: back within 2 s the PLC's watchdog was fed throughout and the motor
                # went on; failed now, the motion would go on unwatched and refuse the next
                rode_out = True
                yield Progress(command, "plc_link", f"{reason}: waiting up to {wait:g} s for it")
                back = await self.coord.wait_link(wait)
                if back.link_up:  # judged again from the next reading on
                    seq = back.seq - 1
                    continue
            if outcome is Outcome.SUCCEEDED:
                yield Result(command, Status.SUCCEEDED, reason)
                return
            if outcome is Outcome.FAILED:
                if not snap.link_up:
                    reason = f"{reason} ({snap.link_error})"
                if reason.startswith("travel timeout") and snap.link_up:
                    await self.coord.write_coil(Coil.MOTION_STOP, True)
                yield self._fail(command, reason)
                return
            if snap.plc is not None:
                pct = spec.read(snap.plc).position_pct
                if abs(pct - last_pct) >= 10.0:
                    last_pct = pct
                    yield Progress(
                        command,
                        f"{spec.name}_moving",
                        f"{spec.name} {pct:.0f} % {spec.open_word}",
                        pct,
                    )

    async def _sequence(
        self, command: str, steps: list[tuple[str, AxisSpec, int, Callable[..., Decision]]]
    ) -> AsyncIterator[Item]:
        for step, spec, direction, check in steps:
            yield Progress(command, step, f"{command}: {step.replace('_', ' ')}")
            result: Result | None = None
            async for item in self._move(step, spec, direction, check):
                if isinstance(item, Result):
                    result = item
                else:
                    yield Progress(command, item.step, item.message, item.percent)
            assert result is not None
            if result.status is not Status.SUCCEEDED:
                yield Result(command, result.status, f"{step}: {result.reason}")
                return
        yield Result(command, Status.SUCCEEDED, f"base {'open' if command == 'open' else 'closed'}")

    async def _open(self, command: CommandParams) -> AsyncIterator[Item]:
        name = command.name
        steps = [
            ("open_panels", PANELS, +1, check_open_panels),
            ("lift_up", LIFT, +1, check_lift_up),
        ]
        async for item in self._sequence(name, steps):
            yield item

    async def _close(self, command: CommandParams) -> AsyncIterator[Item]:
        name = command.name
        steps = [
            ("lift_down", LIFT, -1, check_lift_down),
            ("close_panels", PANELS, -1, check_close_panels),
        ]
        async for item in self._sequence(name, steps):
            yield item

    async def _stop(self, command: CommandParams) -> AsyncIterator[Item]:
        name = command.name
        self._stop_gen += 1
        if not self.coord.snapshot.link_up:
            yield self._fail(
                name,
                "PLC link down: MOTION_STOP not sent (the PLC watchdog stops "
                "all motion within 2 s of losing its master)",
            )
            return
        written = await self.coord.write_coil(Coil.MOTION_STOP, True)
        snap = await self.coord.wait_fresh(written)
        if snap.plc is not None and (snap.plc.panels_moving or snap.plc.lift_moving):
            yield self._fail(name, "MOTION_STOP written but a motor still reports moving")
            return
        yield Result(name, Status.SUCCEEDED, "all motion stopped")

    async def _reset_faults(self, command: CommandParams) -> AsyncIterator[Item]:
        name = command.name
        if not self.coord.snapshot.link_up:
            yield self._fail(name, "PLC link down")
            return
        written = await self.coord.write_coil(Coil.FAULT_RESET, True)
        snap = await self.coord.wait_fresh(written)
        plc = snap.plc
        if plc is None or not snap.link_up:
            yield self._fail(name, "PLC link lost during reset")
            return
        left = plc.fault_bits & MOTION_BLOCKING_FAULTS
        if plc.estop_active:
            yield self._fail(name, "E-stop still active: release it, then reset_faults")
        elif left:
            yield self._fail(name, f"faults still latched: {', '.join(fault_names(left))}")
        else:
            yield Result(
                name, Status.SUCCEEDED, "faults cleared", {"faults": list(plc.fault_names)}
            )
