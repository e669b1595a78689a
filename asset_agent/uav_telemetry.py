"""Pure translation of the autopilot's state into the wire protocol's UAV telemetry and events."""

from __future__ import annotations

from asset_agent.autopilot.state import UavState
from asset_agent.events import Event
from protocol.messages import EventPayload, Severity
from protocol.telemetry_payloads import (
    Attitude,
    Battery,
    Gnss,
    MissionProgress,
    Position,
    UavTelemetry,
    Velocity,
)

FIX = {
    0: "none",
    1: "none",
    2: "2d",
    3: "3d",
    4: "dgps",
    5: "rtk_float",
    6: "rtk_fixed",
    7: "3d",
    8: "3d",
}
LANDED = {
    "UNDEFINED": "unknown",
    "ON_GROUND": "on_ground",
    "IN_AIR": "in_air",
    "TAKEOFF": "takeoff",
    "LANDING": "landing",
}
SEVERITY: dict[str, Severity] = {
    "failsafe": "critical",
    "autopilot_lost": "critical",
    "low_battery": "warning",
}
MESSAGES = {
    "armed": "motors armed",
    "took_off": "took off",
    "mission_finished": "mission finished",
    "landing": "landing",
    "landed": "landed",
    "disarmed": "motors disarmed",
    "failsafe": "the autopilot reports a failsafe",
    "low_battery": "battery low",
    "autopilot_lost": "no HEARTBEAT from the autopilot",
    "autopilot_recovered": "autopilot link back",
}


def _clamp(v: float | None, lo: float, hi: float) -> float | None:
    return None if v is None else min(hi, max(lo, v))


def to_telemetry(s: UavState) -> UavTelemetry:
    """One telemetry sample from the autopilot's state."""
    position = None
    if s.lat is not None and s.lon is not None and s.alt_msl is not None:
        position = Position(lat=s.lat, lon=s.lon, alt_msl_m=s.alt_msl, alt_rel_m=s.alt_rel or 0.0)
    velocity = None
    if s.vn is not None and s.ve is not None and s.vd is not None:
        velocity = Velocity(north_m_s=s.vn, east_m_s=s.ve, down_m_s=s.vd)
    attitude = None
    if s.roll_deg is not None and s.pitch_deg is not None and s.yaw_deg is not None:
        attitude = Attitude(roll_deg=s.roll_deg, pitch_deg=s.pitch_deg, yaw_deg=s.yaw_deg)
    mission = None
    if s.mission_total is not None:
        mission = MissionProgress(
            current=max(0, s.mission_current or 0), total=max(0, s.mission_total)
        )
    return UavTelemetry(
        position=position,
        velocity=velocity,
        attitude=attitude,
        heading_deg=None if s.heading_deg is None else s.heading_deg % 360,
        battery=Battery(
            percent=_clamp(s.battery_pct, 0, 100), voltage_v=s.voltage_v, current_a=s.current_a
        ),
        gnss=Gnss(fix=FIX.get(s.fix_type, "none"), satellites=s.satellites, hdop=s.hdop),  # type: ignore[arg-type]
        flight_mode=s.mode,
        armed=s.armed,
        landed_state=LANDED.get(s.landed_state, "unknown"),  # type: ignore[arg-type]
        mission=mission,
    )


def to_event(e: Event) -> EventPayload:
    """One protocol event from a derived autopilot event."""
    detail = dict(e.detail)
    message = MESSAGES.get(e.kind, e.kind.replace("_", " "))
    if e.kind == "waypoint_reached" and "index" in detail:
        message = f"waypoint {detail['index']} reached"
    return EventPayload(
        name=e.kind,
        severity=SEVERITY.get(e.kind, "info"),
        message=message,
        data={
            k: v for k, v in detail.items() if isinstance(v, str | int | float | bool) or v is None
        },
    )
