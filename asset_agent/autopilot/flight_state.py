"""Flight state from what autopilots actually send: the landed state.

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

Mission completion: `mission_watch.py` (MissionWatch), which uses the constants here.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from asset_agent.autopilot.state import UavState

log = logging.getLogger(__name__)

LAND_MODES = ("LAND",)  # land where it is
RETURN_MODES = ("RTL", "SMART_RTL", "AUTO_RTL")  # fly home, then land there
MAV_STATE_STANDBY = 3
NAV_RETURN_TO_LAUNCH, NAV_LAND = 20, 21
FINAL_COMMANDS = (NAV_RETURN_TO_LAUNCH, NAV_LAND)
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
