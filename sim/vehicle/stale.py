"""The previous mission's end, delivered late, repeated or early: a link's stale view, on request.

A ground station that starts a flight right after another meets the last mission's end again:
the simulator, like the autopilot the issue met, keeps the finished mission's state (COMPLETE,
MISSION_CURRENT on the old last item) across a new upload until MISSION_START runs the new one,
so the MISSION_CURRENT streamed in between already says so; and a telemetry radio or a router
that queues, retries or reorders hands over the old MISSION_CURRENT and MISSION_ITEM_REACHED
after the new upload and the arming, more than once, or ahead of the new upload's MISSION_ACK.

`StaleMission` (the fault, off by default; POST /vehicle/faults/stale_mission) replays the old
end, captured when the next upload begins, at the moments that hurt most:
- `before_ack`: just before the new upload's MISSION_ACK ACCEPTED;
- `on_arming`: when the vehicle arms after that upload;
- `on_start`: right after MISSION_START puts it in AUTO, before the new mission's first
  MISSION_CURRENT has gone out;
each time `repeat` copies. The MISSION_CURRENT is the old one whole: its seq, total, state
COMPLETE and, on 4.5+ habits, the old plan's mission_id (the same as the new one's when the
same items went up again).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle.constants import MISSION_COMPLETE
from sim.vehicle.mission_report import mission_current_message

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter

MOMENTS = ("before_ack", "on_arming", "on_start")


@dataclass
class StaleMission:
    """The fault's switches and the captured end of the previous mission."""

    enabled: bool = False
    before_ack: bool = True
    on_arming: bool = True
    on_start: bool = True
    repeat: int = 1
    replayed: int = 0  # messages replayed so far (the control interface shows it)
    _end: list[Any] = field(default_factory=list)  # the old mission's last messages
    _due: set[str] = field(default_factory=set)  # moments still to come for this upload

    def upload_began(self, c: Copter) -> None:
        """A new mission upload starts: remember how the old one ended, if it did."""
        self._end = []
        self._due = set()
        if c.guidance.mission_state != MISSION_COMPLETE or len(c.items) <= 1:
            return
        self._end = [
            mission_current_message(c),
            mavlink.MAVLink_mission_item_reached_message(c.mission_current),
        ]
        self._due = set(MOMENTS)

    def replay(self, c: Copter, moment: str) -> None:
        """At `moment`, send the old end `repeat` times (once per upload and moment)."""
        if moment not in self._due:
            return
        self._due.discard(moment)
        if not (self.enabled and getattr(self, moment)):
            return
        for _ in range(self.repeat):
            for msg in self._end:
                c.send(msg)
                self.replayed += 1

    def status(self) -> dict[str, Any]:
        """The switches, whether an old end is held, and how many messages went out."""
        return {
            "enabled": self.enabled,
            "before_ack": self.before_ack,
            "on_arming": self.on_arming,
            "on_start": self.on_start,
            "repeat": self.repeat,
            "captured": bool(self._end),
            "replayed": self.replayed,
        }
