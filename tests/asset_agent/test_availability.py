"""Pure availability check."""

from __future__ import annotations

from dataclasses import replace

from asset_agent.autopilot.state import UavState
from asset_agent.availability import AvailabilityLimits, check_availability

READY = UavState(
    link_up=True, sensors_healthy=True, battery_pct=95, fix_type=3, armed=False, system_status=3
)


def test_ready_uav_is_available() -> None:
    assert check_availability(READY) == []


def test_each_failed_condition_reports_value_and_limit() -> None:
    bad = replace(
        READY, link_up=False, sensors_healthy=False, battery_pct=40, fix_type=1, armed=True
    )
    failed = {f.name: f for f in check_availability(bad, AvailabilityLimits(min_battery_pct=80))}
    assert set(failed) == {"autopilot_link", "autopilot_healthy", "battery", "gnss_fix", "disarmed"}
    assert (failed["battery"].value, failed["battery"].limit) == (40, 80)
    assert (failed["gnss_fix"].value, failed["gnss_fix"].limit) == ("NO_FIX", "3D")
    assert failed["disarmed"].value is True


def test_unknown_battery_and_failsafe_are_failures() -> None:
    names = [f.name for f in check_availability(replace(READY, battery_pct=None, system_status=5))]
    assert names == ["autopilot_healthy", "battery"]


def test_rtk_fix_requirement() -> None:
    limits = AvailabilityLimits(min_fix_type=6)
    assert [f.name for f in check_availability(READY, limits)] == ["gnss_fix"]
    assert check_availability(replace(READY, fix_type=6), limits) == []
