"""The simulated autopilot's precision landing in flight: LANDING_TARGET in, the estimator run every
step, and LAND as ArduPilot flies it with PLND on (`Habits.plnd`; the estimator is plnd.py)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

from sim.vehicle.constants import CRITICAL, INFO, WARNING
from sim.vehicle.fence import PARAM_INT8, PARAM_REAL32
from sim.vehicle.plnd import ArduPrecLand
from sim.vehicle.precland import TargetReading

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter
    from sim.vehicle.guidance import Guidance


def landing_target(c: Copter, msg: Any) -> None:
    """LANDING_TARGET: to ArduPilot's precision landing (habit) or the simulator's own, while
    PLND_ENABLED and PLND_TYPE say companion computer; otherwise ignored, as ArduPilot has no
    companion backend to hand it to (there a change of either needs a reboot; here at once)."""
    if not _takes_landing_target(c):
        return
    reading = TargetReading(
        msg.frame, msg.angle_x, msg.angle_y, msg.distance, msg.x, msg.y, msg.z,
        bool(msg.position_valid),
    )  # fmt: skip
    est = c.estimated_position()
    s = c.dyn.state
    if c.plnd is not None:
        reason = c.plnd.handle(reading, c.t)
    else:
        reason = c.precland.handle(
            reading, c.t, (est[0], est[1]), s.altitude, (s.roll, s.pitch, s.yaw)
        )
    if reason:
        c.text(WARNING, reason, throttle_s=2.0)


def _takes_landing_target(c: Copter) -> bool:
    """PLND_ENABLED = 1 and PLND_TYPE = 1 (companion computer over MAVLink); an autopilot without
    the parameters has no precision landing to take it."""
    params = c.fence.params
    return all(params.get(name, (0.0,))[0] == 1 for name in ("PLND_ENABLED", "PLND_TYPE"))


def precision_landing_habit(c: Copter) -> ArduPrecLand | None:
    """ArduPilot's PLND when the habit has it, with PLND_XY_DIST_MAX in the autopilot's
    parameters for a companion to set (ArduPilot 4; 3.x had none). Every habit has
    PLND_ENABLED and PLND_TYPE, set up for a companion computer (1, 1; ArduPilot's defaults are
    0, 0): a UAV configured for precision landing. (ArduPilot hides the group's other
    parameters while PLND_ENABLED is 0; not modelled.)"""
    c.fence.params["PLND_ENABLED"] = (1.0, PARAM_INT8)
    c.fence.params["PLND_TYPE"] = (1.0, PARAM_INT8)
    params = c.config.habits.plnd
    if params is None:
        return None
    if params.has_xy_dist_max:
        c.fence.params["PLND_XY_DIST_MAX"] = (params.xy_dist_max, PARAM_REAL32)
    return ArduPrecLand(params)


def plnd_update(c: Copter, dt: float) -> None:
    """ArduPilot's precision landing runs every loop (Copter::update_precland), reading its
    parameters as it goes (a PARAM_SET takes effect at the next loop)."""
    if c.plnd is None:
        return
    radius = c.fence.params.get("PLND_XY_DIST_MAX")
    if radius is not None and radius[0] != c.plnd.p.xy_dist_max:
        c.plnd.p = replace(c.plnd.p, xy_dist_max=radius[0])
    s = c.dyn.state
    est = c.estimated_position()
    c.plnd.update(c.t, dt, (s.roll, s.pitch, s.yaw), s.velocity[:2], est, s.altitude)
    for text in c.plnd.texts:
        c.text(CRITICAL if text.endswith("Lost") else INFO, text)
    c.plnd.texts.clear()


def land_with_plnd(guidance: Guidance) -> None:
    """LAND as ArduPilot flies it with precision landing on (`Habits.plnd`, sim/vehicle/plnd.py):
    towards the target while it is acquired (else on to where it was last), at LAND's speed
    unless precision landing holds or slows the descent; a retry flies to its position."""
    c, dyn, cfg = guidance.c, guidance.c.dyn, guidance.c.config
    assert c.plnd is not None
    err = c.reading.error_ned
    est = c.estimated_position()
    d = c.plnd.descent(c.t, est, cfg.land_speed)
    if d.retry_ned is not None:
        n, e, down = d.retry_ned
        dyn.set_position_target((n - err[0], e - err[1], down), yaw=guidance.yaw_target)
        return
    if d.target_ne is not None:
        guidance.goal = replace(guidance.goal, n=d.target_ne[0], e=d.target_ne[1])
    alt = dyn.state.altitude
    descend = cfg.land_speed if alt < cfg.land_alt_low else cfg.land_speed_high
    if d.descent is not None:
        descend = min(descend, d.descent)
    n, e = guidance.goal.n - err[0], guidance.goal.e - err[1]
    if descend <= 0:
        dyn.set_position_target((n, e, dyn.state.position[2]), yaw=guidance.yaw_target)
    else:
        dyn.set_position_target((n, e, 1.0), yaw=guidance.yaw_target, speed_down=descend)
