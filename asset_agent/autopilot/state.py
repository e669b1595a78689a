"""The UAV's state as the agent sees it: one frozen value, rebuilt from each MAVLink message."""

from __future__ import annotations

from dataclasses import dataclass

COPTER_MODES = {
    0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL",
    7: "CIRCLE", 9: "LAND", 11: "DRIFT", 13: "SPORT", 14: "FLIP", 15: "AUTOTUNE",
    16: "POSHOLD", 17: "BRAKE", 18: "THROW", 19: "AVOID_ADSB", 20: "GUIDED_NOGPS",
    21: "SMART_RTL", 22: "FLOWHOLD", 23: "FOLLOW", 24: "ZIGZAG", 25: "SYSTEMID",
    26: "AUTOROTATE", 27: "AUTO_RTL",
}  # fmt: skip
MODE_NUMBERS = {name: number for number, name in COPTER_MODES.items()}

FIX_NAMES = {
    0: "NO_GPS", 1: "NO_FIX", 2: "2D", 3: "3D", 4: "DGPS", 5: "RTK_FLOAT", 6: "RTK_FIXED",
    7: "STATIC", 8: "PPP",
}  # fmt: skip
LANDED_STATES = {0: "UNDEFINED", 1: "ON_GROUND", 2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
MISSION_STATES = {
    0: "UNKNOWN", 1: "NO_MISSION", 2: "NOT_STARTED", 3: "ACTIVE", 4: "PAUSED", 5: "COMPLETE",
}  # fmt: skip


@dataclass(frozen=True)
class UavState:
    """Everything the agent knows about the UAV; None until the autopilot has said it.

    Mission indices are in the server's numbering: item 0 is the first item after home
    (MAVLink seq 1), and `mission_total` excludes home.
    """

    link_up: bool = False
    lat: float | None = None  # degrees
    lon: float | None = None
    alt_msl: float | None = None  # metres
    alt_rel: float | None = None  # metres above home
    vn: float | None = None  # m/s, NED
    ve: float | None = None
    vd: float | None = None
    heading_deg: float | None = None
    roll_deg: float | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    battery_pct: float | None = None
    voltage_v: float | None = None
    current_a: float | None = None
    fix_type: int = 0
    satellites: int | None = None
    hdop: float | None = None
    mode: str = "UNKNOWN"
    custom_mode: int | None = None
    armed: bool = False
    system_status: int | None = None
    sensors_healthy: bool | None = None
    landed_state: str = "UNDEFINED"
    mission_current: int | None = None
    mission_total: int | None = None
    mission_state: str = "UNKNOWN"
    mission_id: int | None = None  # MISSION_CURRENT.mission_id: the plan's id (0: none given)
    home_lat: float | None = None
    home_lon: float | None = None
    home_alt_msl: float | None = None
    fence_breached: bool = False  # FENCE_STATUS.breach_status
    fence_breach_count: int | None = None  # FENCE_STATUS.breach_count (None: none heard yet)
    fence_breach_type: str = "NONE"  # NONE | MINALT | MAXALT | BOUNDARY

    @property
    def fix_name(self) -> str:
        """The GNSS fix as a name: NO_FIX, 3D, RTK_FLOAT, RTK_FIXED, ..."""
        return FIX_NAMES.get(self.fix_type, str(self.fix_type))

    @property
    def mode_known(self) -> bool:
        """A HEARTBEAT has been heard: the mode and whether armed are the autopilot's word."""
        return self.custom_mode is not None

    @property
    def landed_known(self) -> bool:
        """The landed state is known (EXTENDED_SYS_STATE, or inferred: flight_state.py)."""
        return self.landed_state != "UNDEFINED"

    @property
    def in_air(self) -> bool:
        """True when the autopilot reports it is not on the ground."""
        return self.landed_state in ("IN_AIR", "TAKEOFF", "LANDING")

    @property
    def failsafe(self) -> bool:
        """True when the autopilot reports MAV_STATE_CRITICAL or EMERGENCY."""
        return self.system_status in (5, 6)


@dataclass(frozen=True)
class Notification:
    """Something the autopilot said that is not state: status text, item reached, link change."""

    kind: str  # "statustext" | "item_reached" | "link_lost" | "link_recovered"
    text: str = ""
    severity: int = 6  # MAV_SEVERITY
    index: int | None = None  # item_reached: index in the server's list (seq - 1)
    # the vehicle's state when it was said (the client sets it): events derived from states and
    # from notifications keep the order in which the autopilot's messages came (EventTracker.feed)
    state: UavState | None = None
