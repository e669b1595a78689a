"""The simulated autopilot's battery failsafe, as ArduCopter's (events.cpp).

Below `CopterConfig.failsafe_battery_pct` in flight: "Battery Failsafe" and the HEARTBEAT's
system_status CRITICAL (`any_failsafe_triggered`), whatever the action; then the action of
BATT_FS_LOW_ACT (`failsafe_battery_action`): none (ArduPilot's default), LAND or RTL. A landing
(LAND, RTL's descent) goes on as LAND when FS_OPTIONS has CONTINUE_IF_LANDING
(`failsafe_continue_landing`); a mode the vehicle is in already is kept; an RTL refused (no
position) is a LAND (`set_mode_RTL_or_land_with_pause`). ArduPilot's LAND after a failsafe pauses
4 s from the mode's start: not modelled.
"""

from __future__ import annotations

from typing import Any

from sim.vehicle.constants import CRITICAL, LAND, RTL


def check_battery(copter: Any) -> None:
    """Trigger the battery failsafe once, in flight, when the battery runs low."""
    if copter.failsafe or not copter.flying:
        return
    if copter.dyn.state.battery_pct >= copter.config.failsafe_battery_pct:
        return
    copter.failsafe = True
    copter.text(CRITICAL, "Battery Failsafe")
    cfg, action = copter.config, copter.config.failsafe_battery_action
    landing = copter.mode == LAND or (copter.mode == RTL and copter.guidance.rtl_phase == "land")
    if landing and cfg.failsafe_continue_landing and action != "none":
        action = "land"
    mode = {"land": LAND, "rtl": RTL}.get(action)
    if mode is None or mode == copter.mode:
        return
    if not copter.set_mode(mode) and mode == RTL:
        copter.set_mode(LAND)
