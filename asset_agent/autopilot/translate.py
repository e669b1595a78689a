"""Pure translation from MAVLink messages to `UavState`: one function per message type.

The functions read message attributes only (any object with the MAVLink field names works),
so they are tested without a link.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from asset_agent.autopilot.state import COPTER_MODES, LANDED_STATES, MISSION_STATES, UavState

MAV_MODE_FLAG_SAFETY_ARMED = 128
MISSION_ID_OFFSET = 6  # MISSION_CURRENT: seq, total (uint16), mission_state, mission_mode (uint8)
OPAQUE_ID_OFFSET = 4  # MISSION_ACK: target system, component, type, mission_type (uint8)
SENSOR_PREARM_CHECK = 0x10000000
# MAV_SYS_STATUS_SENSOR: gyro, accel, mag, baro, GPS, AHRS, battery, pre-arm checks
CRITICAL_SENSORS = 0x1 | 0x2 | 0x4 | 0x8 | 0x20 | 0x200000 | 0x2000000 | SENSOR_PREARM_CHECK


def _heartbeat(s: UavState, m: Any) -> UavState:
    return replace(
        s,
        mode=COPTER_MODES.get(m.custom_mode, f"MODE_{m.custom_mode}"),
        custom_mode=m.custom_mode,
        armed=bool(m.base_mode & MAV_MODE_FLAG_SAFETY_ARMED),
        system_status=m.system_status,
    )


def _sys_status(s: UavState, m: Any) -> UavState:
    # only the sensors a flight depends on: a missing RC receiver on a companion-driven
    # vehicle, or an optional rangefinder, must not make it unavailable
    enabled = m.onboard_control_sensors_enabled & CRITICAL_SENSORS
    healthy = (m.onboard_control_sensors_health & enabled) == enabled
    return replace(
        s,
        sensors_healthy=healthy,
        voltage_v=m.voltage_battery / 1000.0 if m.voltage_battery != 0xFFFF else s.voltage_v,
        current_a=m.current_battery / 100.0 if m.current_battery >= 0 else s.current_a,
        battery_pct=float(m.battery_remaining) if m.battery_remaining >= 0 else s.battery_pct,
    )


def _battery_status(s: UavState, m: Any) -> UavState:
    cells = [v for v in m.voltages if v != 0xFFFF]
    return replace(
        s,
        voltage_v=sum(cells) / 1000.0 if cells else s.voltage_v,
        current_a=m.current_battery / 100.0 if m.current_battery >= 0 else s.current_a,
        battery_pct=float(m.battery_remaining) if m.battery_remaining >= 0 else s.battery_pct,
    )


def _global_position(s: UavState, m: Any) -> UavState:
    return replace(
        s,
        lat=m.lat / 1e7,
        lon=m.lon / 1e7,
        alt_msl=m.alt / 1000.0,
        alt_rel=m.relative_alt / 1000.0,
        vn=m.vx / 100.0,
        ve=m.vy / 100.0,
        vd=m.vz / 100.0,
        heading_deg=m.hdg / 100.0 if m.hdg != 0xFFFF else s.heading_deg,
    )


def _attitude(s: UavState, m: Any) -> UavState:
    return replace(
        s,
        roll_deg=math.degrees(m.roll),
        pitch_deg=math.degrees(m.pitch),
        yaw_deg=math.degrees(m.yaw) % 360.0,
    )


def _gps_raw(s: UavState, m: Any) -> UavState:
    return replace(
        s,
        fix_type=m.fix_type,
        satellites=m.satellites_visible if m.satellites_visible != 255 else None,
        hdop=m.eph / 100.0 if m.eph != 0xFFFF else None,
    )


def _extended_sys_state(s: UavState, m: Any) -> UavState:
    return replace(s, landed_state=LANDED_STATES.get(m.landed_state, "UNDEFINED"))


def extension_u32(m: Any, name: str, offset: int) -> int:
    """A uint32 MAVLink 2 extension field: from the message when this pymavlink knows the field,
    else read from the payload at `offset` (pymavlink 2.4.50 stops before MISSION_CURRENT's
    mission_id and MISSION_ACK's opaque_id, added to common.xml in 2023); 0 when not sent
    (MAVLink 2 truncates trailing zeros; MAVLink 1 has no extensions)."""
    known = getattr(m, name, None)
    if isinstance(known, int):
        return known
    get = getattr(m, "get_msgbuf", None)
    buf = bytes(get()) if callable(get) else b""
    if len(buf) < 10 or buf[0] != 0xFD:  # not a MAVLink 2 frame
        return 0
    payload = buf[10 : 10 + buf[1]].ljust(offset + 4, b"\0")
    return int(struct.unpack_from("<I", payload, offset)[0])


def _mission_current(s: UavState, m: Any) -> UavState:
    # total excludes home (on the last item seq == total); 0 = not reported, 0xFFFF = no mission
    total = getattr(m, "total", 0)
    state = getattr(m, "mission_state", 0)
    if total == 0xFFFF:
        mission_total: int | None = 0
    elif total:
        mission_total = total
    else:
        mission_total = s.mission_total
    return replace(
        s,
        mission_current=max(m.seq - 1, 0),
        mission_total=mission_total,
        # 0: not reported (ArduPilot before 4.4): keep what flight_state.MissionWatch inferred
        mission_state=MISSION_STATES.get(state, "UNKNOWN") if state else s.mission_state,
        mission_id=extension_u32(m, "mission_id", MISSION_ID_OFFSET),
    )


def _home(s: UavState, m: Any) -> UavState:
    return replace(
        s, home_lat=m.latitude / 1e7, home_lon=m.longitude / 1e7, home_alt_msl=m.altitude / 1000.0
    )


FENCE_BREACH_TYPES = {0: "NONE", 1: "MINALT", 2: "MAXALT", 3: "BOUNDARY"}


def _fence_status(s: UavState, m: Any) -> UavState:
    return replace(
        s,
        fence_breached=bool(m.breach_status),
        fence_breach_count=int(m.breach_count),
        fence_breach_type=FENCE_BREACH_TYPES.get(m.breach_type, str(m.breach_type)),
    )


TRANSLATORS: dict[str, Callable[[UavState, Any], UavState]] = {
    "FENCE_STATUS": _fence_status,
    "HEARTBEAT": _heartbeat,
    "SYS_STATUS": _sys_status,
    "BATTERY_STATUS": _battery_status,
    "GLOBAL_POSITION_INT": _global_position,
    "ATTITUDE": _attitude,
    "GPS_RAW_INT": _gps_raw,
    "EXTENDED_SYS_STATE": _extended_sys_state,
    "MISSION_CURRENT": _mission_current,
    "HOME_POSITION": _home,
}


def apply(state: UavState, msg: Any) -> UavState:
    """The state after one message; unknown messages leave it unchanged."""
    fn = TRANSLATORS.get(msg.get_type())
    return fn(state, msg) if fn else state
