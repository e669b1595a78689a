"""Faults injected into the simulated autopilot; the control interface (control.py) sets them."""

from __future__ import annotations

from dataclasses import dataclass, field

from sim.vehicle.stale import StaleMission


@dataclass
class Faults:
    """Injected faults; the control interface sets them."""

    prearm_failure: str | None = None  # reported as "PreArm: <text>"
    mute_until: float = 0.0  # wall time; math.inf = until cleared
    drop_mission: bool = False  # ignore every mission-protocol message
    drop_acks: int = 0  # the next this many COMMAND_ACKs are lost (the command is carried out)
    stale_mission: StaleMission = field(default_factory=StaleMission)  # the last mission's end

    def muted(self, wall: float) -> bool:
        """True while the autopilot answers nothing."""
        return wall < self.mute_until
