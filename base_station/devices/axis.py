"""A motorised axis (panels or lift) seen from the daemon: state, interlock verdicts, tracking.

Everything here is pure: it takes decoded `PlcState` values and wall times, returns values.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

from base_station.plc.codec import PlcState, fault_names
from base_station.plc.registers import MOTION_BLOCKING_FAULTS, Coil, FaultBit

START_GRACE_S = 0.5


class MotionState(StrEnum):
    """State of an axis; for the lift `open` means fully up and `closed` fully down."""

    CLOSED = "closed"
    OPENING = "opening"
    OPEN = "open"
    CLOSING = "closing"
    MOVING = "moving"  # moving in a direction not yet known (e.g. just after a restart)
    STOPPED = "stopped"  # between the limits, not moving
    FAULT = "fault"


@dataclass(frozen=True)
class AxisReading:
    """The limit switches, moving flag, position and stall bit of one axis."""

    at_open: bool
    at_closed: bool
    moving: bool
    position_pct: float
    stalled: bool


@dataclass(frozen=True)
class AxisSpec:
    """Names, coils and register accessors of one axis."""

    name: str
    open_word: str
    closed_word: str
    open_coil: Coil
    close_coil: Coil
    stall_bit: FaultBit
    read: Callable[[PlcState], AxisReading]


@dataclass(frozen=True)
class Decision:
    """An interlock verdict: allowed, or refused with a human-readable reason."""

    allowed: bool
    reason: str = ""
    already_there: bool = False


def motion_blockers(plc: PlcState | None, link_up: bool) -> list[str]:
    """Reasons no motion may start at all (link, E-stop, latched faults)."""
    if not link_up or plc is None:
        return ["PLC link down"]
    reasons = []
    if plc.estop_active:
        reasons.append("E-stop active")
    latched = plc.fault_bits & MOTION_BLOCKING_FAULTS
    if latched:
        reasons.append(f"faults latched: {', '.join(fault_names(latched))} (reset_faults first)")
    return reasons


def refused(command: str, reasons: list[str]) -> Decision:
    """A refusal of `command` listing every reason."""
    return Decision(False, f"{command} refused: " + "; ".join(reasons))


class AxisTracker:
    """Derives the axis state from successive readings (direction from the position trend)."""

    def __init__(self, spec: AxisSpec) -> None:
        self.spec = spec
        self.direction = 0
        self._last_pos: float | None = None

    def commanded(self, direction: int) -> None:
        """The daemon has just commanded motion towards open (+1) or closed (-1)."""
        self.direction = direction

    def update(self, plc: PlcState | None) -> MotionState | None:
        """The state after a new reading (None when nothing is known)."""
        if plc is None:
            return None
        r = self.spec.read(plc)
        if self._last_pos is not None and r.moving and r.position_pct != self._last_pos:
            self.direction = 1 if r.position_pct > self._last_pos else -1
        self._last_pos = r.position_pct
        if not r.moving:
            self.direction = 0
        return motion_state(r, self.direction)


def motion_state(r: AxisReading, direction: int) -> MotionState:
    """State of an axis from its reading and known direction of travel."""
    if r.stalled:
        return MotionState.FAULT
    if r.moving:
        if direction > 0:
            return MotionState.OPENING
        if direction < 0:
            return MotionState.CLOSING
        return MotionState.MOVING
    if r.at_open:
        return MotionState.OPEN
    if r.at_closed:
        return MotionState.CLOSED
    return MotionState.STOPPED


class Outcome(StrEnum):
    """Where a tracked motion stands."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass
class MotionTracker:
    """Follows one commanded motion to its limit, or to the reason it failed."""

    spec: AxisSpec
    direction: int
    started_at: float
    timeout_s: float
    saw_motion: bool = False

    @property
    def verb(self) -> str:
        """E.g. "panels opening"."""
        word = self.spec.open_word if self.direction > 0 else self.spec.closed_word
        return f"{self.spec.name} to {word}"

    def update(
        self, plc: PlcState | None, link_up: bool, now: float, fresh: bool
    ) -> tuple[Outcome, str]:
        """Judge a snapshot; `fresh` = it was read after the command was written."""
        s = self.spec
        if not link_up or plc is None:
            return Outcome.FAILED, f"PLC link lost while moving {self.verb}"
        if plc.estop_active or plc.fault_bits & FaultBit.ESTOP:
            # the four tables are read one after another: either sign of the E-stop counts
            return Outcome.FAILED, f"E-stop pressed while moving {self.verb}"
        r = s.read(plc)
        if plc.fault_bits & s.stall_bit:
            return (
                Outcome.FAILED,
                f"{s.name} motor stall at {r.position_pct:.0f} %: stopped by the PLC",
            )
        latched = plc.fault_bits & MOTION_BLOCKING_FAULTS
        if latched:
            names = ", ".join(fault_names(latched))
            return Outcome.FAILED, f"{names} latched while moving {self.verb}"
        target = r.at_open if self.direction > 0 else r.at_closed
        if target and not r.moving:
            return (
                Outcome.SUCCEEDED,
                f"{s.name} {s.open_word if self.direction > 0 else s.closed_word}",
            )
        elapsed = now - self.started_at
        if elapsed > self.timeout_s:
            return (
                Outcome.FAILED,
                f"travel timeout: {s.name} at {r.position_pct:.0f} % after {elapsed:.1f} s "
                f"(limit {self.timeout_s:.1f} s)",
            )
        if not fresh:
            return Outcome.RUNNING, ""
        if r.moving:
            self.saw_motion = True
            return Outcome.RUNNING, ""
        if not self.saw_motion and plc.interlock_refused:
            return Outcome.FAILED, f"{self.verb} refused by the PLC interlock"
        if not self.saw_motion and elapsed < START_GRACE_S:
            return Outcome.RUNNING, ""
        return (
            Outcome.FAILED,
            f"{s.name} stopped at {r.position_pct:.0f} % before reaching the limit",
        )
