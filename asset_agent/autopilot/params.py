"""Autopilot parameters: PARAM_SET and PARAM_REQUEST_READ answered by PARAM_VALUE, with retries,
and the fence's set.

ArduPilot answers a PARAM_SET with the parameter's PARAM_VALUE (the value it now holds); a
name it does not know gets no answer at all. So a set is retried on silence and fails with
ParamError after the retries, and a PARAM_VALUE with another value fails it at once.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from asset_agent.autopilot.errors import AutopilotError

if TYPE_CHECKING:
    from asset_agent.autopilot.client import Autopilot

MAV_PARAM_TYPE_INT8, MAV_PARAM_TYPE_REAL32 = 2, 9
# ArduCopter's FENCE_TYPE bits (AC_Fence.h): max altitude, home circle, polygons and circles
FENCE_TYPE_ALT_MAX, FENCE_TYPE_CIRCLE, FENCE_TYPE_POLYGON = 1, 2, 4
FENCE_ACTION_RTL = 1  # AC_FENCE_ACTION_RTL_AND_LAND: RTL, or LAND when RTL is impossible


class ParamError(AutopilotError):
    """A parameter could not be set (no answer, or the autopilot kept another value)."""


class NoSuchParam(ParamError):
    """No PARAM_VALUE for the name, every try, the link up all the while: the autopilot has no
    such parameter (or hides it behind its group's disabled switch)."""


def unanswered(ap: Autopilot, name: str) -> bool:
    """`name` went unanswered (NoSuchParam) since the autopilot last booted. A parameter appears
    only with new firmware or a switch that takes a reboot, so a caller for whom its absence is
    harmless need not spend every retry on it again until then."""
    return ap.unanswered_params.get(name) == ap.reboots


def _name(param_id: Any) -> str:
    raw = param_id.decode("ascii", "replace") if isinstance(param_id, bytes) else str(param_id)
    return raw.rstrip("\x00")


async def _answer(ap: Autopilot, name: str, send: Callable[[Any], None]) -> float:
    """Send (`send(mav)`) until the autopilot answers `name`'s PARAM_VALUE; its value."""
    ap.require_link()
    cfg = ap.config
    with ap.tap(lambda m: m.get_type() == "PARAM_VALUE" and _name(m.param_id) == name) as q:
        for _ in range(cfg.command_retries + 1):
            ap.send(send)
            try:
                msg = await asyncio.wait_for(q.get(), cfg.command_timeout_s)
            except TimeoutError:
                continue
            return float(msg.param_value)
    tries = f"{name}: no PARAM_VALUE after {cfg.command_retries + 1} tries"
    if not ap.link_up:
        raise ParamError(f"{tries}, the link lost")
    ap.unanswered_params[name] = ap.reboots
    raise NoSuchParam(tries)


async def read_param(ap: Autopilot, name: str) -> float:
    """The value the autopilot holds (PARAM_REQUEST_READ by name); ParamError when it answers
    nothing: no such parameter (or, on ArduPilot, one hidden by its group's disabled switch)."""
    cfg = ap.config
    wire = name.encode("ascii")
    return await _answer(
        ap,
        name,
        lambda mav: mav.param_request_read_send(cfg.target_system, cfg.target_component, wire, -1),
    )


async def set_param(
    ap: Autopilot, name: str, value: float, param_type: int = MAV_PARAM_TYPE_REAL32
) -> float:
    """Set one parameter and return the value the autopilot reports it now holds."""
    cfg = ap.config
    wire = name.encode("ascii")
    got = await _answer(
        ap,
        name,
        lambda mav: mav.param_set_send(
            cfg.target_system, cfg.target_component, wire, float(value), param_type
        ),
    )
    if not math.isclose(got, float(value), rel_tol=1e-6, abs_tol=1e-6):
        raise ParamError(f"{name}: set to {value}, the autopilot holds {got}")
    return got


async def enable_fence(ap: Autopilot, alt_max_m: float | None) -> dict[str, float]:
    """FENCE_TYPE (polygons and circles, and the altitude ceiling when given), FENCE_ALT_MAX,
    FENCE_ACTION = RTL, then FENCE_ENABLE = 1; the values the autopilot holds."""
    fence_type = FENCE_TYPE_POLYGON | (FENCE_TYPE_ALT_MAX if alt_max_m is not None else 0)
    held = {"FENCE_TYPE": await set_param(ap, "FENCE_TYPE", fence_type, MAV_PARAM_TYPE_INT8)}
    if alt_max_m is not None:
        held["FENCE_ALT_MAX"] = await set_param(ap, "FENCE_ALT_MAX", alt_max_m)
    held["FENCE_ACTION"] = await set_param(
        ap, "FENCE_ACTION", FENCE_ACTION_RTL, MAV_PARAM_TYPE_INT8
    )
    held["FENCE_ENABLE"] = await set_param(ap, "FENCE_ENABLE", 1, MAV_PARAM_TYPE_INT8)
    return held
