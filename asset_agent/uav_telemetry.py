"""Pure translation of the autopilot's state into the wire protocol's UAV telemetry and events.

Autopilots report NaN for values they do not have (ArduPilot's ATTITUDE before the EKF is up, a
battery monitor without a current sensor): a non-finite number is dropped here, field by field, so
the rest of the sample is still sent (the protocol refuses NaN and infinities). A value outside the
protocol's range (a latitude of 200°, which GLOBAL_POSITION_INT's int32 can carry) leaves out its
part of the sample alone, with one warning when the part goes bad (no traceback) and a note when
it is good again, instead of failing the whole sample.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TypeVar

from pydantic import ValidationError

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
    "fence_breach": "critical",
    "landing_aborted": "critical",
    "low_battery": "warning",
    "precland_silent": "warning",
    "landed_without_precision": "warning",
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
    "fence_breach": "geofence breached: the autopilot is returning to the base",
    "autopilot_lost": "no HEARTBEAT from the autopilot",
    "autopilot_recovered": "autopilot link back",
    "landing_aborted": "landing abandoned: the pad was not found (or lost with no retry left) "
    "and the GNSS has no RTK fixed fix, or the wind held the UAV off the pad; holding at a safe "
    "height",
    "precland_silent": "precision landing sends no target while its sensors' readings arrive: "
    "the autopilot lands on GNSS alone",
    "landed_without_precision": "landed on GNSS alone: precision landing sent no target while "
    "its sensors' readings arrived",
}


log = logging.getLogger(__name__)
T = TypeVar("T")
_BAD: set[str] = set()  # the parts left out of the last sample for their values (logged once)


def _part(name: str, build: Callable[[], T | None]) -> T | None:
    """One part of a sample, or None when the autopilot's values for it are out of range."""
    try:
        part = build()
    except ValidationError as err:
        if name not in _BAD:
            _BAD.add(name)
            fields = "; ".join(
                f"{'.'.join(str(p) for p in e['loc'])}={e.get('input')!r}: {e['msg']}"
                for e in err.errors()
            )
            log.warning("autopilot value out of range, %s left out of telemetry: %s", name, fields)
        return None
    if name in _BAD:
        _BAD.discard(name)
        log.info("autopilot values for %s in range again", name)
    return part


def _whole(name: str, model: Callable[..., T], **values: float | None) -> T | None:
    """Part `name` built from `values`, or None when one of them is missing (non-finite) or out
    of range (`_part`)."""
    if any(v is None for v in values.values()):
        return None
    return _part(name, lambda: model(**values))


def _f(v: float | None) -> float | None:
    """The value when it is a finite number, else None (dropped)."""
    return v if v is not None and math.isfinite(v) else None


def _clamp(v: float | None, lo: float, hi: float) -> float | None:
    v = _f(v)
    return None if v is None else min(hi, max(lo, v))


def to_telemetry(s: UavState) -> UavTelemetry:
    """One telemetry sample from the autopilot's state; non-finite values are left out, and each
    part (position, velocity, attitude, battery, GNSS, mission) whose values are out of range."""
    position = _whole(
        "position", Position, lat=_f(s.lat), lon=_f(s.lon), alt_msl_m=_f(s.alt_msl),
        alt_rel_m=_f(s.alt_rel) or 0.0,
    )  # fmt: skip
    velocity = _whole(
        "velocity", Velocity, north_m_s=_f(s.vn), east_m_s=_f(s.ve), down_m_s=_f(s.vd)
    )
    attitude = _whole(
        "attitude", Attitude, roll_deg=_f(s.roll_deg), pitch_deg=_f(s.pitch_deg),
        yaw_deg=_f(s.yaw_deg),
    )  # fmt: skip
    heading = _f(s.heading_deg)
    mission = _part(
        "mission",
        lambda: (
            MissionProgress(current=max(0, s.mission_current or 0), total=max(0, s.mission_total))
            if s.mission_total is not None
            else None
        ),
    )
    battery = _part(
        "battery",
        lambda: Battery(
            percent=_clamp(s.battery_pct, 0, 100),
            voltage_v=_f(s.voltage_v),
            current_a=_f(s.current_a),
        ),
    )
    gnss = _part(
        "gnss",
        lambda: Gnss(fix=FIX.get(s.fix_type, "none"), satellites=s.satellites, hdop=_f(s.hdop)),  # type: ignore[arg-type]
    )
    return UavTelemetry(
        position=position,
        velocity=velocity,
        attitude=attitude,
        heading_deg=None if heading is None else heading % 360,
        battery=battery,
        gnss=gnss,
        flight_mode=s.mode,
        armed=s.armed,
        landed_state=LANDED.get(s.landed_state, "unknown"),  # type: ignore[arg-type]
        mission=mission,
    )


def to_event(e: Event) -> EventPayload:
    """One protocol event from a derived autopilot event."""
    detail = dict(e.detail)
    message = MESSAGES.get(e.kind, e.kind.replace("_", " "))
    if e.kind == "waypoint_reached" and isinstance(detail.get("index"), int):
        # numbered from 1, as the console numbers mission items ("Mission item 1 of 6"); the
        # index stays the server's 0-based one
        detail["number"] = detail["index"] + 1
        message = f"waypoint {detail['number']} reached"
    return EventPayload(
        name=e.kind,
        severity=SEVERITY.get(e.kind, "info"),
        message=message,
        data={
            k: v
            for k, v in detail.items()
            if isinstance(v, str | int | bool)
            or v is None
            or (isinstance(v, float) and _f(v) is not None)
        },
    )
