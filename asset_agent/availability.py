"""Pure availability check: can this UAV take a mission now? Each failed condition with value and limit."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from asset_agent.autopilot.state import FIX_NAMES, UavState


@dataclass(frozen=True)
class AvailabilityLimits:
    """What the UAV needs to be available."""

    min_battery_pct: float = 80.0
    min_fix_type: int = 3  # 3D fix


@dataclass(frozen=True)
class FailedCondition:
    """One unmet condition: its name, the measured value, the limit and a sentence."""

    name: str
    value: Any
    limit: Any
    message: str


def check_availability(
    state: UavState, limits: AvailabilityLimits | None = None
) -> list[FailedCondition]:
    """Every unmet condition (an empty list means available)."""
    limits = limits or AvailabilityLimits()
    failed: list[FailedCondition] = []
    if not state.link_up:
        failed.append(
            FailedCondition("autopilot_link", False, True, "no HEARTBEAT from the autopilot")
        )
    if state.sensors_healthy is not True or state.failsafe:
        value = "failsafe" if state.failsafe else state.sensors_healthy
        failed.append(
            FailedCondition(
                "autopilot_healthy",
                value,
                True,
                "autopilot reports unhealthy sensors or a failsafe",
            )
        )
    if state.battery_pct is None or state.battery_pct < limits.min_battery_pct:
        failed.append(
            FailedCondition("battery", state.battery_pct, limits.min_battery_pct,
                            f"battery {state.battery_pct}% below {limits.min_battery_pct}%")
        )  # fmt: skip
    if state.fix_type < limits.min_fix_type:
        need = FIX_NAMES.get(limits.min_fix_type, str(limits.min_fix_type))
        failed.append(
            FailedCondition(
                "gnss_fix", state.fix_name, need, f"GNSS fix {state.fix_name}, need {need}"
            )
        )
    if state.armed:
        failed.append(FailedCondition("disarmed", True, False, "the UAV is armed"))
    return failed
