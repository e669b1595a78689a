"""The simulated autopilot's habits: how a real ArduPilot Copter release behaves, as named options.

Each habit was modelled from ArduPilot's source (ArduPilot/ardupilot) and from what the releases
did when an agent flew them (issue 13: ArduCopter 3.7-dev and 4.7.0-dev SITL):

| habit | ArduPilot 4.x | ArduPilot 3.7 | source |
|---|---|---|---|
| `message_interval` | honoured | `MAV_RESULT_UNSUPPORTED` | 3.7 SITL answered UNSUPPORTED to every SET_MESSAGE_INTERVAL |
| `message_interval_silent` | off | off | no release; a link that drops the command (tests the no-answer path) |
| REQUEST_DATA_STREAM | honoured (groups below) | honoured | `ArduCopter/GCS_Mavlink.cpp` `STREAM_*_msgs` |
| `stream_buckets` | a message given a rate is sent first one interval later, or with a bucket already at that interval; asked again at its own rate, unchanged | a stream turned on is sent at the next 50 Hz tick; one already on at its old count | 4.x `GCS_MAVLINK::set_ap_message_interval` (the bucket of that interval, else a new one with `last_sent_ms` now; REQUEST_DATA_STREAM goes through it too); 3.x `GCS_MAVLINK::stream_trigger` (a stream that was off has its tick count at 0) |
| `mode_heartbeat` | a HEARTBEAT at once on every mode change | at the next 1 Hz beat only | 4.x `Copter::set_mode` (ArduCopter/mode.cpp: `gcs().send_message(MSG_HEARTBEAT)` once the mode is set); the 3.6-era `set_mode` read sends none |
| `extended_sys_state` | sent when asked | never | 3.7 SITL sent none; in Copter's stream groups it is in none |
| `mission_current_extensions` | MISSION_CURRENT.total / mission_state | seq only | MAVLink fields added in 2023 (4.4+) |
| `mission_ids` | MISSION_ACK.opaque_id and MISSION_CURRENT.mission_id: a CRC32 of the stored plan | none | 4.5+ `MissionItemProtocol::opaque_id` (sim/vehicle/mission_report.py) |
| `ardupilot_storage` | params packed | packed | `AP_Mission::mavlink_int_to_mission_cmd` / `mission_cmd_to_mavlink_int` |
| `streams_at_boot` | HEARTBEAT only | HEARTBEAT only | a companion port's `SRn_*` rates default to 0 |
| `boot_s` | ~35 s to armable | ~40 s | pre-arm checks fail until the EKF and GPS are ready |
| reboot | `MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN`, refused when armed | same | `GCS_MAVLINK::handle_preflight_reboot` |
| `uptime` | `time_boot_ms` on the simulation's clock (SITL) | same | `AP_HAL_SITL/system.cpp`: `millis64()` is the scheduler's stopped clock, the simulated time: `--speedup` times the wall's, and behind it when the process is starved |
| speed | `WPNAV_SPEED` (10 m/s) until DO_CHANGE_SPEED | same | `AC_WPNav` defaults |
| `mission_fence` | fence and rally over the mission protocol (types 1, 2), said in AUTOPILOT_VERSION | the old FENCE_POINT protocol only | `MissionItemProtocol_Fence` / `_Rally` came with 4.0 |
| `plnd` | ArduPilot's PLND (plnd.py) | same, angle fields only | `AC_PrecLand*`, `PosVelEKF`, Copter `mode.cpp` |

`Habits()` (no profile named) keeps this simulator's historic defaults: every habit of 4.x but
with every stream on at boot and no boot delay, so tests and the demo need not wait, and the
simulator's own precision landing (a LANDING_TARGET moves the landing point at once).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace
from typing import Literal

from sim.vehicle import mission as ms
from sim.vehicle.plnd import PlndParams

# MAV_CMDs whose position ArduPilot keeps (AP_Mission::stored_in_location)
STORED_IN_LOCATION = (16, 17, 18, 19, 21, 22, 30, 31, 82, 92, 179, 189, 191, 201, 84, 85, 94)


@dataclass(frozen=True)
class Habits:
    """How the simulated autopilot behaves where real releases differ (see the module table)."""

    name: str = "sim"
    message_interval: bool = True  # False: SET_MESSAGE_INTERVAL -> MAV_RESULT_UNSUPPORTED
    message_interval_silent: bool = False  # True: SET_MESSAGE_INTERVAL gets no answer at all
    stream_buckets: bool = True  # False: a data stream turned on is sent at once (3.x)
    mode_heartbeat: bool = True  # False: a mode change is told by the next 1 Hz HEARTBEAT only
    extended_sys_state: bool = True  # False: EXTENDED_SYS_STATE is never sent
    mission_current_extensions: bool = True  # False: MISSION_CURRENT carries seq only
    mission_ids: bool = True  # False: no plan id in MISSION_ACK / MISSION_CURRENT (before 4.5)
    ardupilot_storage: bool = True  # pack mission params as AP_Mission stores them
    mission_fence: bool = True  # False: no MAV_PROTOCOL_CAPABILITY_MISSION_FENCE / _RALLY
    streams_at_boot: Literal["all", "heartbeat"] = "all"
    boot_s: float = 0.0  # simulated seconds from boot to armable
    reboot_s: float = 2.0  # wall seconds of silence while rebooting
    # time_boot_ms: wall milliseconds since boot (a flight controller) or simulated ones (SITL)
    uptime: Literal["wall", "simulated"] = "wall"
    # precision landing: None, the simulator's own (a LANDING_TARGET moves the landing point at
    # once); PlndParams, ArduPilot's PLND with the companion backend (sim/vehicle/plnd.py)
    plnd: PlndParams | None = None
    prearm_texts: tuple[str, ...] = (
        "AHRS: waiting for home",
        "GPS 1: Bad fix",
        "Need Position Estimate",
    )


PROFILES: dict[str, Habits] = {
    "ardupilot-4": Habits(
        name="ardupilot-4",
        streams_at_boot="heartbeat",
        boot_s=35.0,
        plnd=PlndParams(),
        uptime="simulated",
    ),
    "ardupilot-3.7": Habits(
        name="ardupilot-3.7",
        message_interval=False,
        stream_buckets=False,
        mode_heartbeat=False,
        extended_sys_state=False,
        mission_current_extensions=False,
        mission_ids=False,
        mission_fence=False,
        streams_at_boot="heartbeat",
        boot_s=40.0,
        uptime="simulated",
        prearm_texts=("EKF attitude is bad", "Need 3D Fix", "Need Position Estimate"),
        # 3.x read the angle fields only, and LAND never held its descent for the target
        plnd=PlndParams(position_fields=False, xy_dist_max=0.0, has_xy_dist_max=False),
    ),
}


def profile(name: str, **overrides: object) -> Habits:
    """A named profile with some habits overridden (e.g. ``boot_s=2`` in tests)."""
    try:
        base = PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown autopilot profile {name!r}: one of {sorted(PROFILES)}") from None
    return replace(base, **overrides)  # type: ignore[arg-type]


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def _uint(v: float, bits: int) -> float:
    """A float param stored in an unsigned C field: NaN -> 0, truncated, wrapped."""
    if math.isnan(v) or math.isinf(v):
        return 0.0
    return float(int(v) % (1 << bits))


def _int8(v: float) -> float:
    if math.isnan(v) or math.isinf(v):
        return 0.0
    return float((int(v) + 128) % 256 - 128)


def _int16(v: float) -> float:
    if math.isnan(v) or math.isinf(v):
        return 0.0
    return float((int(v) + 32768) % 65536 - 32768)


def stored(item: ms.Item) -> ms.Item:
    """`item` as ArduPilot reads it back after storing it (AP_Mission's packing).

    Params ArduPilot does not keep come back 0, NaN in an integer field comes back 0, the
    altitude is kept in whole centimetres, the position only for commands that have one (the
    frame then GLOBAL or GLOBAL_RELATIVE_ALT, never the _INT forms), autocontinue is always 1.
    """
    p1, p2, p3, p4 = item.param1, item.param2, item.param3, item.param4
    c = item.command
    out = (0.0, 0.0, 0.0, 0.0)
    if c in (16, 22, 82):  # WAYPOINT hold time, TAKEOFF pitch, SPLINE hold: cmd.p1 (uint16)
        out = (_uint(p1, 16), 0.0, 0.0, 0.0)
    elif c == 21:  # LAND: p1 abort alt; param4 comes back as the loiter direction, +-1
        out = (_uint(p1, 16), 0.0, 0.0, -1.0 if p4 < 0 else 1.0)
    elif c == 17:  # LOITER_UNLIM: radius magnitude in p1, sign as direction
        r = _uint(abs(p3) if not math.isnan(p3) else 0.0, 16)
        out = (0.0, 0.0, -r if p3 < 0 else r, 0.0)
    elif c == 18:  # LOITER_TURNS: turns low byte, radius high byte, direction, xtrack
        r = _uint(abs(p3) if not math.isnan(p3) else 0.0, 8)
        out = (_uint(p1, 8), 0.0, -r if p3 < 0 else r, 1.0 if p4 == 1 else 0.0)
    elif c == 19:  # LOITER_TIME: seconds, direction +-1, xtrack
        out = (_uint(p1, 16), 0.0, -1.0 if p3 < 0 else 1.0, 1.0 if p4 == 1 else 0.0)
    elif c == 93:  # NAV_DELAY: seconds (float), hour/min/sec (int8)
        out = (_f32(p1), _int8(p2), _int8(p3), _int8(p4))
    elif c == 112:  # CONDITION_DELAY
        out = (_f32(p1), 0.0, 0.0, 0.0)
    elif c == 115:  # CONDITION_YAW: angle, rate (float), direction (int8), relative (uint8)
        out = (_f32(p1), _f32(p2), _int8(p3), _uint(p4, 8))
    elif c == 177:  # DO_JUMP: target (uint16), repeat (int16)
        out = (_uint(p1, 16), _int16(p2), 0.0, 0.0)
    elif c == 178:  # DO_CHANGE_SPEED: type (uint8), speed, throttle (float)
        out = (_uint(p1, 8), _f32(p2), _f32(p3), 0.0)
    elif c == 20:  # RTL: nothing
        out = (0.0, 0.0, 0.0, 0.0)
    else:  # the rest as sent (float32)
        out = (_f32(p1), _f32(p2), _f32(p3), _f32(p4))
    if c in STORED_IN_LOCATION:
        frame = 3 if item.frame in (ms.FRAME_GLOBAL_RELATIVE_ALT, 6) else item.frame
        frame = 0 if frame in (ms.FRAME_GLOBAL, 5, 2) else frame
        frame = 10 if frame == 11 else frame
        cm = int(_f32(item.z * 100.0))
        x, y, z = item.x, item.y, cm / 100.0
    else:
        frame, x, y, z = 0, 0, 0, 0.0
    return replace(
        item, frame=frame, param1=out[0], param2=out[1], param3=out[2], param4=out[3],
        x=x, y=y, z=z, autocontinue=1,
    )  # fmt: skip
