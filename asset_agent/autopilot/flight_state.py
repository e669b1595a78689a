"""Flight state from what autopilots actually send: landed state and mission completion.

Landed state: EXTENDED_SYS_STATE.landed_state once the autopilot has sent one (ArduPilot 4.x,
PX4; the adapter asks for it). Until then, and for autopilots that never send it (ArduPilot
3.x), `infer_landed_state` reads it from HEARTBEAT (armed, system_status) and
GLOBAL_POSITION_INT (relative altitude, vertical speed), with `Thresholds`:

| from | to | when |
|---|---|---|
| any | ON_GROUND | disarmed, or system_status STANDBY (ArduPilot and PX4 report ACTIVE when armed) |
| ON_GROUND / UNDEFINED | TAKEOFF | armed and climbing faster than `climb_mps` (0.5 m/s) or above `airborne_alt_m` (1 m) |
| TAKEOFF | IN_AIR | above `airborne_alt_m` and the climb below `still_mps` (0.3 m/s): the take-off altitude is reached |
| IN_AIR | LANDING | in LAND / RTL / SMART_RTL / AUTO_RTL and descending faster than `descent_mps` (0.3 m/s) |
| LANDING | LANDING | while still in one of those modes (a pause in the descent is no take-off) |
| IN_AIR / LANDING / TAKEOFF | ON_GROUND | below `airborne_alt_m` with the vertical speed under `still_mps` (touched down; the disarm follows) |

A hover below 1 m reads as ON_GROUND; no flight of this platform does that.

Mission completion: MISSION_CURRENT.mission_state when the autopilot reports it (ArduPilot 4.4+,
PX4 1.14+). Otherwise `MissionWatch` marks it COMPLETE when
- MISSION_ITEM_REACHED names the last item (seq == item count: home is seq 0), or
- the vehicle, in AUTO on the last item, disarms (a LAND / RTL last item ends on the ground), or
- in AUTO on the last item, the mode changes to a non-AUTO mode that the agent did not ask for
  in the previous `own_mode_change_s` (2 s) (PX4 switches to HOLD at the end of a mission).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from asset_agent.autopilot.state import UavState

LANDING_MODES = ("LAND", "RTL", "SMART_RTL", "AUTO_RTL")
MAV_STATE_STANDBY = 3


@dataclass(frozen=True)
class Thresholds:
    """The numbers of the landed-state inference (see the module table)."""

    airborne_alt_m: float = 1.0
    climb_mps: float = 0.5
    still_mps: float = 0.3
    descent_mps: float = 0.3


def infer_landed_state(prev: str, s: UavState, t: Thresholds | None = None) -> str:
    """The landed state implied by `s`, given the one inferred before (`prev`)."""
    t = t or Thresholds()
    if not s.armed or s.system_status == MAV_STATE_STANDBY:
        return "ON_GROUND"
    if s.alt_rel is None or s.vd is None:
        return prev if prev != "UNDEFINED" else "ON_GROUND"
    climb = -s.vd
    low = s.alt_rel < t.airborne_alt_m
    if prev in ("UNDEFINED", "ON_GROUND"):
        return "TAKEOFF" if climb > t.climb_mps or not low else "ON_GROUND"
    if low and abs(climb) < t.still_mps:
        return "ON_GROUND"
    if prev == "TAKEOFF":
        return "IN_AIR" if not low and climb < t.still_mps else "TAKEOFF"
    if s.mode in LANDING_MODES and (prev == "LANDING" or -climb > t.descent_mps):
        return "LANDING"
    return "IN_AIR"


class MissionWatch:
    """Infers mission completion for autopilots whose MISSION_CURRENT has no mission_state."""

    def __init__(self, own_mode_change_s: float = 2.0) -> None:
        self.own_mode_change_s = own_mode_change_s
        self.reported = False  # the autopilot reports mission_state itself
        self.total: int | None = None  # items without home
        self._asked_mode_at = -1e9

    def uploaded(self, count: int) -> None:
        """A mission of `count` items (home excluded) went up: a fresh mission."""
        self.total = count

    def asked_mode(self, now: float) -> None:
        """The agent itself changed the mode now."""
        self._asked_mode_at = now

    def on_reached(self, s: UavState, seq: int) -> UavState:
        """MISSION_ITEM_REACHED(seq)."""
        total = s.mission_total or self.total
        if not self.reported and total and seq >= total:
            return replace(s, mission_state="COMPLETE")
        return s

    def on_change(self, prev: UavState, cur: UavState, now: float) -> UavState:
        """A new state from any message: completion by disarm or mode change on the last item."""
        if self.reported or cur.mission_state == "COMPLETE":
            return cur
        total = cur.mission_total or self.total
        if not total or prev.mode != "AUTO" or prev.mission_current != total - 1:
            return self._started(prev, cur)
        if prev.armed and not cur.armed:
            return replace(cur, mission_state="COMPLETE")
        own = now - self._asked_mode_at < self.own_mode_change_s
        if cur.mode not in ("AUTO", "UNKNOWN") and not own:
            return replace(cur, mission_state="COMPLETE")
        return cur

    def _started(self, prev: UavState, cur: UavState) -> UavState:
        if cur.mode == "AUTO" and cur.armed and cur.mission_state in ("UNKNOWN", "NOT_STARTED"):
            return replace(cur, mission_state="ACTIVE")
        return cur
