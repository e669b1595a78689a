"""Telemetry of the simulated autopilot: message builders and the stream scheduler (wall time)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle.constants import AUTO, BRAKE, GUIDED, LAND, LOITER, ON_GROUND, RTL
from sim.vehicle.mission_report import mission_current_message

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter

HEARTBEAT, SYS_STATUS, SYSTEM_TIME, GPS_RAW_INT, ATTITUDE = 0, 1, 2, 24, 30
LOCAL_POSITION_NED, GLOBAL_POSITION_INT, MISSION_CURRENT, VFR_HUD = 32, 33, 42, 74
BATTERY_STATUS, HOME_POSITION, EXTENDED_SYS_STATE = 147, 242, 245
SIMSTATE = 164  # ArduPilot SITL's own truth (ardupilotmega dialect), in the EXTRA1 group

# MAV_SYS_STATUS_SENSOR bits: gyro, accel, mag, baro, gps, motor outputs, battery, prearm
SENSORS = 0x1 | 0x2 | 0x4 | 0x8 | 0x20 | 0x8000 | 0x2000000 | 0x10000000
PREARM_BIT = 0x10000000
GPS_BIT = 0x20


def _heartbeat(c: Copter) -> Any:
    base_mode = 1 | 16  # custom mode enabled, stabilize
    if c.mode in (AUTO, GUIDED, RTL, LAND, LOITER, BRAKE):
        base_mode |= 8
    if c.armed:
        base_mode |= 128
    # as GCS_MAVLINK_Copter::vehicle_system_status: CRITICAL on any failsafe, STANDBY while the
    # land detector says landed (armed or not: an armed copter on the ground is STANDBY too),
    # otherwise ACTIVE
    on_ground = c.guidance.landed_state() == ON_GROUND
    status = 5 if c.failsafe else 3 if on_ground else 4  # CRITICAL, STANDBY, ACTIVE
    return mavlink.MAVLink_heartbeat_message(2, 3, base_mode, c.mode, status, 3)


def _sys_status(c: Copter) -> Any:
    s = c.dyn.state
    health = SENSORS
    if c.prearm_failure(arming=False) is not None and not c.armed:
        health &= ~PREARM_BIT
    if c.reading.fix_type < 3:
        health &= ~GPS_BIT
    return mavlink.MAVLink_sys_status_message(
        SENSORS, SENSORS, health, 200, round(s.voltage * 1000), round(s.current_a * 100),
        round(s.battery_pct), 0, 0, 0, 0, 0, 0,
    )  # fmt: skip


def _battery(c: Copter) -> Any:
    s = c.dyn.state
    cells = c.config.dynamics.cells
    per_cell = round(s.voltage * 1000 / cells)
    volts = [per_cell] * cells + [65535] * (10 - cells)
    return mavlink.MAVLink_battery_status_message(
        0, 0, 1, 2500, volts, round(s.current_a * 100), round(s.consumed_mah), -1,
        round(s.battery_pct),
    )  # fmt: skip


def _estimated_geodetic(c: Copter) -> tuple[float, float, float]:
    n, e, d = c.estimated_position()
    return c.origin.to_geodetic(n, e, d)


def _global_position(c: Copter) -> Any:
    s = c.dyn.state
    lat, lon, alt = _estimated_geodetic(c)
    hdg = round(math.degrees(s.yaw) % 360 * 100)
    vn, ve, vd = (round(v * 100) for v in s.velocity)
    return mavlink.MAVLink_global_position_int_message(
        c.time_boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
        round(s.altitude * 1000), vn, ve, vd, hdg,
    )  # fmt: skip


def _local_position(c: Copter) -> Any:
    n, e, d = c.estimated_position()
    v = c.dyn.state.velocity
    return mavlink.MAVLink_local_position_ned_message(c.time_boot_ms, n, e, d, v[0], v[1], v[2])


def _yaw(c: Copter) -> float:
    """The vehicle's heading as MAVLink carries it: radians in [-pi, pi)."""
    return (c.dyn.state.yaw + math.pi) % (2 * math.pi) - math.pi


def _simstate(c: Copter) -> Any:
    """The simulator's truth, as SITL sends it (SITL::simstate_send): attitude and lat/lng of the
    simulated vehicle, not of the autopilot's estimate."""
    s = c.dyn.state
    lat, lon, _ = c.origin.to_geodetic(*s.position)
    return mavlink.MAVLink_simstate_message(
        s.roll, s.pitch, _yaw(c), 0, 0, 0, 0, 0, 0, round(lat * 1e7), round(lon * 1e7)
    )


def _attitude(c: Copter) -> Any:
    s = c.dyn.state
    return mavlink.MAVLink_attitude_message(c.time_boot_ms, s.roll, s.pitch, _yaw(c), 0, 0, 0)


def _gps_raw(c: Copter) -> Any:
    r = c.reading
    n, e, d = c.dyn.state.position
    lat, lon, alt = c.origin.to_geodetic(n + r.error_ned[0], e + r.error_ned[1], d + r.error_ned[2])
    v = c.dyn.state.velocity
    speed = math.hypot(v[0], v[1])
    cog = round(math.degrees(math.atan2(v[1], v[0])) % 360 * 100) if speed > 0.2 else 65535
    return mavlink.MAVLink_gps_raw_int_message(
        round(c.t * 1e6), r.fix_type, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
        round(r.hdop * 100), round(r.hdop * 150), round(speed * 100), cog, r.satellites,
        round(alt * 1000), round(r.h_acc_m * 1000), round(r.h_acc_m * 1500),
    )  # fmt: skip


def _system_time(c: Copter) -> Any:
    return mavlink.MAVLink_system_time_message(0, c.time_boot_ms)


def _vfr_hud(c: Copter) -> Any:
    s = c.dyn.state
    speed = math.hypot(s.velocity[0], s.velocity[1])
    hdg = round(math.degrees(s.yaw)) % 360
    alt = c.origin.alt + s.altitude
    return mavlink.MAVLink_vfr_hud_message(
        speed, speed, hdg, 50 if c.armed else 0, alt, -s.velocity[2]
    )


def _home(c: Copter) -> Any:
    o = c.origin
    return mavlink.MAVLink_home_position_message(
        round(o.lat * 1e7), round(o.lon * 1e7), round(o.alt * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0
    )


def _extended_sys_state(c: Copter) -> Any:
    return mavlink.MAVLink_extended_sys_state_message(0, c.guidance.landed_state())


BUILDERS: dict[int, Callable[[Copter], Any]] = {
    HEARTBEAT: _heartbeat,
    SYS_STATUS: _sys_status,
    SYSTEM_TIME: _system_time,
    GPS_RAW_INT: _gps_raw,
    ATTITUDE: _attitude,
    LOCAL_POSITION_NED: _local_position,
    GLOBAL_POSITION_INT: _global_position,
    MISSION_CURRENT: mission_current_message,
    VFR_HUD: _vfr_hud,
    BATTERY_STATUS: _battery,
    HOME_POSITION: _home,
    EXTENDED_SYS_STATE: _extended_sys_state,
    SIMSTATE: _simstate,
}

DEFAULT_INTERVALS: dict[int, float | None] = {
    HEARTBEAT: 1.0,
    SYS_STATUS: 0.5,
    SYSTEM_TIME: 1.0,
    GPS_RAW_INT: 0.2,
    ATTITUDE: 0.1,
    LOCAL_POSITION_NED: 0.2,
    GLOBAL_POSITION_INT: 0.2,
    MISSION_CURRENT: 1.0,
    VFR_HUD: 0.5,
    BATTERY_STATUS: 1.0,
    HOME_POSITION: 5.0,
    EXTENDED_SYS_STATE: 1.0,
    SIMSTATE: 0.1,
}

# REQUEST_DATA_STREAM groups, as ArduCopter files its messages (GCS_Mavlink.cpp STREAM_*_msgs);
# EXTENDED_SYS_STATE and HOME_POSITION are in no group: only SET_MESSAGE_INTERVAL or a request
DATA_STREAMS: dict[int, tuple[int, ...]] = {
    1: (),  # RAW_SENSORS: IMU messages, not simulated
    2: (SYS_STATUS, GPS_RAW_INT, MISSION_CURRENT),  # EXTENDED_STATUS
    3: (),  # RC_CHANNELS
    6: (GLOBAL_POSITION_INT, LOCAL_POSITION_NED),  # POSITION
    10: (ATTITUDE, SIMSTATE),  # EXTRA1 (SIMSTATE in SITL builds)
    11: (VFR_HUD,),  # EXTRA2
    12: (SYSTEM_TIME, BATTERY_STATUS),  # EXTRA3
}


MIN_INTERVAL_MS = 5  # the simulator's fastest stream (ArduPilot caps at 0.8 x its loop rate)


class StreamScheduler:
    """Which telemetry message is due when (wall seconds); SET_MESSAGE_INTERVAL edits it."""

    def __init__(self, now: float = 0.0, quiet: bool = False, at_once: bool = False) -> None:
        # quiet: only HEARTBEAT until asked (a companion port whose SRn_ rates are 0); at_once:
        # a data stream turned on is sent at once (habit `stream_buckets` off, ArduPilot 3.x)
        self.at_once = at_once
        self.intervals: dict[int, float | None] = dict(DEFAULT_INTERVALS)
        if quiet:
            self.intervals = {k: (v if k == HEARTBEAT else None) for k, v in self.intervals.items()}
        self._next: dict[int, float] = dict.fromkeys(self.intervals, now)
        self._once: list[int] = []
        self._now = now  # the latest time `due` was asked at

    def set_interval(self, msg_id: int, interval_us: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 stops, 0 restores the default, else microseconds
        (whole milliseconds, as ArduPilot keeps them). ArduPilot 4.x's message buckets
        (`set_ap_message_interval`, GCS_Common.cpp): a message given the interval it already has
        keeps its schedule ("don't need to move it"); given the interval of another message, it
        joins that message's bucket and is sent with it; else it gets a new bucket whose
        `last_sent_ms` is now, so its first message comes one interval later (5 s for a
        HOME_POSITION asked at 0.2 Hz). HEARTBEAT, a deferred message, starts over. A request
        (MAV_CMD_REQUEST_MESSAGE) is sent at once."""
        if msg_id not in BUILDERS:
            return False
        old = self.intervals[msg_id]
        if interval_us < 0:
            new = None
        elif interval_us == 0:
            new = DEFAULT_INTERVALS[msg_id]
        else:
            new = max(int(interval_us) // 1000, MIN_INTERVAL_MS) / 1000
        self.intervals[msg_id] = new
        if new is None or (new == old and msg_id != HEARTBEAT):  # HEARTBEAT: deferred, anew
            return True
        mate = None if msg_id == HEARTBEAT else self._bucket_of(new, msg_id)
        self._next[msg_id] = self._next[mate] if mate is not None else self._now + new
        return True

    def _bucket_of(self, interval: float, msg_id: int) -> int | None:
        """Another message sent every `interval` (its bucket), if any."""
        for other, every in self.intervals.items():
            if every == interval and other not in (msg_id, HEARTBEAT):
                return other
        return None

    def request_data_stream(self, stream_id: int, rate_hz: int, start: int) -> None:
        """REQUEST_DATA_STREAM: set every message of a group (0 = all) to `rate_hz`, or stop them.
        4.x: each through `set_interval` (its buckets); 3.x (`at_once`): `stream_trigger` fires
        a stream that was off at its next tick, and one that was on when its old count runs
        out, at the new rate after that."""
        groups = DATA_STREAMS.values() if stream_id == 0 else [DATA_STREAMS.get(stream_id, ())]
        for group in groups:
            for msg_id in group:
                if not (start and rate_hz > 0):
                    self.set_interval(msg_id, -1)
                elif not self.at_once:
                    self.set_interval(msg_id, 1e6 / rate_hz)
                else:
                    if self.intervals[msg_id] is None:
                        self._next[msg_id] = self._now
                    self.intervals[msg_id] = 1.0 / min(rate_hz, 50)

    def send_once(self, msg_id: int) -> bool:
        """MAV_CMD_REQUEST_MESSAGE: send `msg_id` at the next opportunity."""
        if msg_id not in BUILDERS:
            return False
        self._once.append(msg_id)
        return True

    def due(self, now: float) -> list[int]:
        """Message ids to send now; advances their schedule."""
        out, self._once = self._once, []
        self._now = now
        for msg_id, interval in self.intervals.items():
            if interval is None or now < self._next.get(msg_id, 0.0):
                continue
            out.append(msg_id)
            nxt = self._next.get(msg_id, 0.0) + interval
            self._next[msg_id] = nxt if nxt > now else now + interval
        return out


def build(c: Copter, msg_id: int) -> Any:
    """The current value of telemetry message `msg_id`."""
    return BUILDERS[msg_id](c)
