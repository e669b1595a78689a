"""Flight state from what autopilots actually send: landed state and mission completion.

Landed state: EXTENDED_SYS_STATE.landed_state once the autopilot has sent one (ArduPilot 4.x,
PX4; the adapter asks for it). Until then, and for autopilots that never send it (ArduPilot
3.x), `infer_landed_state` reads it from HEARTBEAT (armed, system_status), GLOBAL_POSITION_INT
(relative altitude, vertical speed, position), HOME_POSITION and the current mission item, with
`Thresholds`:

| from | to | when |
|---|---|---|
| any | ON_GROUND | disarmed, or system_status STANDBY (ArduPilot: while its land detector says landed, armed or not; PX4 reports ACTIVE when armed) |
| ON_GROUND / UNDEFINED | TAKEOFF | armed and climbing faster than `climb_mps` (0.5 m/s) or above `airborne_alt_m` (1 m) |
| TAKEOFF | IN_AIR | above `airborne_alt_m` and the climb below `still_mps` (0.3 m/s): the take-off altitude is reached |
| IN_AIR | LANDING | descending faster than `descent_mps` (0.3 m/s) while landing where it is (LAND mode, or AUTO on a NAV_LAND item), or while returning (RTL / SMART_RTL / AUTO_RTL mode, or AUTO on a NAV_RETURN_TO_LAUNCH item) within `home_radius_m` (5 m) of home: RTL's final descent, never its climb or a descent on the way |
| LANDING | LANDING | while still landing or returning (a pause in the descent is no take-off) |
| IN_AIR / TAKEOFF | ON_GROUND | below `airborne_alt_m` with the vertical speed under `still_mps` (touched down; the disarm follows) |
| LANDING | ON_GROUND | below `airborne_alt_m` with the vertical speed under `landing_still_mps` (0.08 m/s: a precision landing's final descent, ArduPilot PLND's 0.1-0.25 m/s below 2 m, is no touchdown) |

A hover below 1 m reads as ON_GROUND; no flight of this platform does that.

Mission completion (`MissionWatch`): the mission counts as finished once, until the next upload
or a restart in AUTO on an earlier item, when
- MISSION_ITEM_REACHED names its last navigation item (ArduPilot sends it when the item is
  verified: a waypoint on arrival, a NAV_LAND / RTL item at touchdown, ModeAuto::verify_RTL), or
- the vehicle, in AUTO, having flown an earlier item since the upload (not a stale
  MISSION_CURRENT of the last flight), starts its last item and that item is
  NAV_RETURN_TO_LAUNCH or NAV_LAND: the survey is over, the vehicle is heading home (ArduPilot
  reports COMPLETE only after the touchdown, and never if the run switches to RTL meanwhile: a
  mode change stops AP_Mission, whose MISSION_CURRENT.mission_state then reads NOT_STARTED), or
- MISSION_CURRENT.mission_state says COMPLETE (ArduPilot 4.4+, PX4 1.14+).
For autopilots that do not report mission_state (before ArduPilot 4.4) also when
- the vehicle, in AUTO on the last item, disarms (a LAND / RTL last item ends on the ground), or
- in AUTO on the last item, the mode changes to a non-AUTO mode that the agent did not ask for
  in the previous `own_mode_change_s` (2 s) (PX4 switches to HOLD at the end of a mission).
The agent's own RTL or LAND on a last RTL / LAND item finishes it by the second rule (it has
started); its RTL or LAND earlier (an abort) does not.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from asset_agent.autopilot.state import UavState

log = logging.getLogger(__name__)

LAND_MODES = ("LAND",)  # land where it is
RETURN_MODES = ("RTL", "SMART_RTL", "AUTO_RTL")  # fly home, then land there
MAV_STATE_STANDBY = 3
NAV_RETURN_TO_LAUNCH, NAV_LAND = 20, 21
FINAL_COMMANDS = (NAV_RETURN_TO_LAUNCH, NAV_LAND)
NAV_COMMAND_MAX = 99  # MAV_CMD_NAV_* are 16..99; DO_* and CONDITION_* come after
EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class Thresholds:
    """The numbers of the landed-state inference (see the module table)."""

    airborne_alt_m: float = 1.0
    climb_mps: float = 0.5
    still_mps: float = 0.3
    landing_still_mps: float = 0.08  # below PLND's slowest descent, 0.1 m/s
    descent_mps: float = 0.3
    home_radius_m: float = 5.0


def home_distance_m(s: UavState) -> float | None:
    """Horizontal metres from the vehicle to home (flat earth), None while either is unknown."""
    lat, lon, home_lat, home_lon = s.lat, s.lon, s.home_lat, s.home_lon
    if lat is None or lon is None or home_lat is None or home_lon is None:
        return None
    dn = math.radians(home_lat - lat) * EARTH_RADIUS_M
    de = math.radians(home_lon - lon) * EARTH_RADIUS_M * math.cos(math.radians(lat))
    return math.hypot(dn, de)


def landing_kind(s: UavState, command: int | None = None) -> str | None:
    """How the vehicle would come down now: "land" where it is (LAND mode, AUTO on a NAV_LAND
    item), "return" home first (RTL-like modes, AUTO on an RTL item), or None; `command` is the
    MAV_CMD of the current mission item, when known."""
    if s.mode in LAND_MODES or (s.mode == "AUTO" and command == NAV_LAND):
        return "land"
    if s.mode in RETURN_MODES or (s.mode == "AUTO" and command == NAV_RETURN_TO_LAUNCH):
        return "return"
    return None


def infer_landed_state(
    prev: str, s: UavState, t: Thresholds | None = None, command: int | None = None
) -> str:
    """The landed state implied by `s`, given the one inferred before (`prev`); `command` is the
    MAV_CMD of the current mission item when known (AUTO flying a NAV_LAND or RTL item)."""
    t = t or Thresholds()
    if not s.armed or s.system_status == MAV_STATE_STANDBY:
        return "ON_GROUND"
    if s.alt_rel is None or s.vd is None:
        return prev if prev != "UNDEFINED" else "ON_GROUND"
    climb = -s.vd
    low = s.alt_rel < t.airborne_alt_m
    if prev in ("UNDEFINED", "ON_GROUND"):
        return "TAKEOFF" if climb > t.climb_mps or not low else "ON_GROUND"
    # a precision landing's final metres are slower than still_mps (ArduPilot's PLND descends at
    # 0.1-0.25 m/s between 2 m and 0.35 m): while landing, touched down means stopped
    if low and abs(climb) < (t.landing_still_mps if prev == "LANDING" else t.still_mps):
        return "ON_GROUND"
    if prev == "TAKEOFF":
        return "IN_AIR" if not low and climb < t.still_mps else "TAKEOFF"
    kind = landing_kind(s, command)
    if kind is None:
        return "IN_AIR"
    if prev == "LANDING":
        return "LANDING"
    if -climb <= t.descent_mps:
        return "IN_AIR"
    if kind == "return":
        home = home_distance_m(s)
        if home is None or home > t.home_radius_m:
            return "IN_AIR"  # descending on the way home (RTL_CONE, terrain): not the landing
    return "LANDING"


class MissionWatch:
    """Tells when the mission is finished, from whatever the autopilot sends (module docstring)."""

    def __init__(self, own_mode_change_s: float = 2.0) -> None:
        self.own_mode_change_s = own_mode_change_s
        self.reported = False  # the autopilot reports mission_state itself
        self.total: int | None = None  # items without home
        self.commands: list[int] = []  # the uploaded mission's MAV_CMDs, server index order
        self.finished: str | None = None  # why the mission counts as finished, once
        self.progressed = False  # seen flying an item before the last since the upload
        self._asked_mode_at = -1e9

    def uploaded(self, count: int, commands: Sequence[int] = ()) -> None:
        """A mission of `count` items (home excluded) went up: a fresh mission."""
        self.total = count
        self.commands = list(commands)
        self.finished = None
        self.progressed = False

    def asked_mode(self, now: float) -> None:
        """The agent itself changed the mode now."""
        self._asked_mode_at = now

    def command_at(self, index: int | None) -> int | None:
        """The MAV_CMD of item `index` (server numbering) of the uploaded mission, if known."""
        if index is None or not 0 <= index < len(self.commands):
            return None
        return self.commands[index]

    def last_nav_index(self, total: int | None) -> int | None:
        """The index of the mission's last navigation item (its last item if commands unknown)."""
        for i in range(len(self.commands) - 1, -1, -1):
            if self.commands[i] <= NAV_COMMAND_MAX:
                return i
        return total - 1 if total else None

    def on_reached(self, s: UavState, seq: int) -> UavState:
        """MISSION_ITEM_REACHED(seq): the last navigation item reached finishes the mission."""
        last = self.last_nav_index(s.mission_total or self.total)
        if last is not None and seq - 1 >= last:
            return self._finish(s, f"item {seq - 1}, the last, reached")
        return s

    def on_change(self, prev: UavState, cur: UavState, now: float) -> UavState:
        """A new state from any message: the rules of the module docstring."""
        total = cur.mission_total or self.total
        last = self.last_nav_index(total)
        if self.finished is not None:
            if not _before(cur, last):
                return replace(cur, mission_state="COMPLETE")
            self.finished = None  # restarted
            cur = replace(cur, mission_state="ACTIVE")
        self.progressed = self.progressed or _before(prev, last) or _before(cur, last)
        if cur.mission_state == "COMPLETE":
            return self._finish(cur, "the autopilot reports it complete")
        command = self.command_at(cur.mission_current)
        if (  # a stale MISSION_CURRENT (the last flight's last item) at the start is not it
            self.progressed
            and cur.mode == "AUTO"
            and cur.armed
            and last is not None
            and cur.mission_current == last
            and command in FINAL_COMMANDS
        ):
            name = "RTL" if command == NAV_RETURN_TO_LAUNCH else "LAND"
            return self._finish(cur, f"the last item ({name}) started")
        if self.reported:
            return cur
        if not total or prev.mode != "AUTO" or prev.mission_current != total - 1:
            return self._started(prev, cur)
        if prev.armed and not cur.armed:
            return self._finish(cur, "disarmed in AUTO on the last item")
        own = now - self._asked_mode_at < self.own_mode_change_s
        if cur.mode not in ("AUTO", "UNKNOWN") and not own:
            return self._finish(cur, f"left AUTO for {cur.mode} on the last item")
        return cur

    def _finish(self, s: UavState, why: str) -> UavState:
        if self.finished is None:
            self.finished = why
            self.progressed = False
            log.info("mission finished: %s", why)
        return replace(s, mission_state="COMPLETE")

    def _started(self, prev: UavState, cur: UavState) -> UavState:
        if cur.mode == "AUTO" and cur.armed and cur.mission_state in ("UNKNOWN", "NOT_STARTED"):
            return replace(cur, mission_state="ACTIVE")
        return cur


def _before(s: UavState, last: int | None) -> bool:
    """Flying the mission (armed, AUTO) on an item before `last`."""
    if s.mode != "AUTO" or not s.armed or s.mission_current is None or last is None:
        return False
    return s.mission_current < last
