"""Pure availability check: can this UAV take a mission now? Every condition with value and limit."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from asset_agent.autopilot.state import FIX_NAMES, UavState
from protocol.vocabulary import AvailabilityCondition, AvailabilityReport


@dataclass(frozen=True)
class AvailabilityLimits:
    """What the UAV needs to be available."""

    min_battery_pct: float = 80.0
    min_fix_type: int = 3  # 3D fix


def conditions(
    state: UavState, limits: AvailabilityLimits | None = None
) -> list[AvailabilityCondition]:
    """Every condition, met or not: autopilot link and health, battery, GNSS fix, disarmed."""
    limits = limits or AvailabilityLimits()
    healthy = state.sensors_healthy is True and not state.failsafe
    battery_ok = state.battery_pct is not None and state.battery_pct >= limits.min_battery_pct
    need = FIX_NAMES.get(limits.min_fix_type, str(limits.min_fix_type))
    return [
        AvailabilityCondition(
            name="autopilot_link", ok=state.link_up, value=state.link_up, limit=True,
            message="HEARTBEAT from the autopilot" if state.link_up
            else "no HEARTBEAT from the autopilot",
        ),
        AvailabilityCondition(
            name="autopilot_healthy", ok=healthy,
            value="failsafe" if state.failsafe else state.sensors_healthy, limit=True,
            message="autopilot healthy" if healthy
            else "autopilot reports unhealthy sensors or a failsafe",
        ),
        AvailabilityCondition(
            name="battery", ok=battery_ok, value=state.battery_pct, limit=limits.min_battery_pct,
            message=f"battery {state.battery_pct}% "
            f"{'at or above' if battery_ok else 'below'} {limits.min_battery_pct}%",
        ),
        AvailabilityCondition(
            name="gnss_fix", ok=state.fix_type >= limits.min_fix_type, value=state.fix_name,
            limit=need, message=f"GNSS fix {state.fix_name}, need {need}",
        ),
        AvailabilityCondition(
            name="disarmed", ok=not state.armed, value=state.armed, limit=False,
            message="the UAV is armed" if state.armed else "the UAV is disarmed",
        ),
    ]  # fmt: skip


def check_availability(
    state: UavState, limits: AvailabilityLimits | None = None
) -> list[AvailabilityCondition]:
    """Every unmet condition (an empty list means available)."""
    return [c for c in conditions(state, limits) if not c.ok]


def report(
    state: UavState,
    limits: AvailabilityLimits | None = None,
    more: Sequence[AvailabilityCondition] = (),
) -> AvailabilityReport:
    """The `check_availability` answer: every condition (the state's, then `more`, those the
    daemon had to ask the autopilot for), the failed ones repeated."""
    return AvailabilityReport.of([*conditions(state, limits), *more])
