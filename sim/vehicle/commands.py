"""COMMAND_LONG / COMMAND_INT handling of the simulated autopilot: one function per command."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sim.vehicle.constants import (
    ACCEPTED,
    AUTO,
    FAILED,
    FORCE_MAGIC,
    LAND,
    RTL,
    UNSUPPORTED,
)  # fmt: skip

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter

Params = tuple[float, float, float, float, float, float, float]

# MAV_CMD numbers
NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF = 20, 21, 22
DO_SET_MODE, DO_CHANGE_SPEED, MISSION_START, COMPONENT_ARM_DISARM = 176, 178, 300, 400
GET_HOME_POSITION, SET_MESSAGE_INTERVAL, REQUEST_MESSAGE = 410, 511, 512
REQUEST_AUTOPILOT_CAPABILITIES = 520
CONDITION_YAW = 115
PREFLIGHT_REBOOT_SHUTDOWN = 246
NO_ANSWER = -1  # not a MAV_RESULT: send no COMMAND_ACK at all


def _arm_disarm(c: Copter, p: Params, link: Any) -> int:
    force = int(p[1]) == FORCE_MAGIC
    if p[0] < 0.5:
        return c.disarm(force)
    result = c.arm(force)
    if result == ACCEPTED:
        c.faults.stale_mission.replay(c, "on_arming")  # the fault (stale.py)
    return result


def _takeoff(c: Copter, p: Params, link: Any) -> int:
    return c.guidance.takeoff(p[6])


def _land(c: Copter, p: Params, link: Any) -> int:
    return ACCEPTED if c.set_mode(LAND) else FAILED


def _rtl(c: Copter, p: Params, link: Any) -> int:
    return ACCEPTED if c.set_mode(RTL) else FAILED


def _set_mode(c: Copter, p: Params, link: Any) -> int:
    if not int(p[0]) & 1:  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        return UNSUPPORTED
    return ACCEPTED if c.set_mode(int(p[1])) else FAILED


def _mission_start(c: Copter, p: Params, link: Any) -> int:
    if not c.armed or len(c.items) <= 1 or not c.set_mode(AUTO):
        return FAILED
    c.faults.stale_mission.replay(c, "on_start")  # the fault (stale.py): before the new item's
    return ACCEPTED


def _change_speed(c: Copter, p: Params, link: Any) -> int:
    if not 0.0 < p[1] <= 50.0:
        return FAILED
    c.guidance.speed = p[1]
    g = c.guidance.goal
    if g.kind == "goto" and g.speed is not None:
        from dataclasses import replace

        c.guidance.goal = replace(g, speed=p[1])
    return ACCEPTED


def _condition_yaw(c: Copter, p: Params, link: Any) -> int:
    if not c.armed:
        return FAILED
    c.guidance.condition_yaw(p[0], p[2], bool(p[3]))
    return ACCEPTED


def _message_interval(c: Copter, p: Params, link: Any) -> int:
    if c.config.habits.message_interval_silent:
        return NO_ANSWER  # dropped on the way (a router, a firmware that ignores it)
    if not c.config.habits.message_interval:
        return UNSUPPORTED  # ArduPilot 3.7: no MAV_CMD_SET_MESSAGE_INTERVAL
    streams = c.streams_for(link)
    if streams is None:
        return FAILED
    return ACCEPTED if streams.set_interval(int(p[0]), p[1]) else FAILED


def _request_message(c: Copter, p: Params, link: Any) -> int:
    streams = c.streams_for(link)
    if streams is None:
        return FAILED
    return ACCEPTED if streams.send_once(int(p[0])) else FAILED


def _capabilities(c: Copter, p: Params, link: Any) -> int:
    """MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: AUTOPILOT_VERSION to the asking link."""
    c.send(c.autopilot_version(), link)
    return ACCEPTED


def _home(c: Copter, p: Params, link: Any) -> int:
    return _request_message(c, (242, 0, 0, 0, 0, 0, 0), link)


def _reboot(c: Copter, p: Params, link: Any) -> int:
    if round(p[0]) != 1:  # 1: reboot the autopilot; shutdown and the companion's are not ours
        return UNSUPPORTED
    return c.reboot()


COMMANDS: dict[int, Callable[[Copter, Params, Any], int]] = {
    COMPONENT_ARM_DISARM: _arm_disarm,
    NAV_TAKEOFF: _takeoff,
    NAV_LAND: _land,
    NAV_RETURN_TO_LAUNCH: _rtl,
    DO_SET_MODE: _set_mode,
    MISSION_START: _mission_start,
    DO_CHANGE_SPEED: _change_speed,
    CONDITION_YAW: _condition_yaw,
    SET_MESSAGE_INTERVAL: _message_interval,
    REQUEST_MESSAGE: _request_message,
    GET_HOME_POSITION: _home,
    PREFLIGHT_REBOOT_SHUTDOWN: _reboot,
    REQUEST_AUTOPILOT_CAPABILITIES: _capabilities,
}


def run_command(c: Copter, command: int, params: Params, link: Any) -> int:
    """Execute one MAV_CMD; the MAV_RESULT for its COMMAND_ACK."""
    handler = COMMANDS.get(command)
    if handler is None:
        return UNSUPPORTED
    return handler(c, params, link)
