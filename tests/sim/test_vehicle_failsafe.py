"""The simulated autopilot's battery failsafe (sim/vehicle/failsafe.py), as ArduCopter's
handle_battery_failsafe: the HEARTBEAT says CRITICAL whatever the action; the action of
BATT_FS_LOW_ACT, a landing going on with FS_OPTIONS' CONTINUE_IF_LANDING."""

from __future__ import annotations

import pytest

from sim.vehicle.constants import GUIDED, LAND, RTL
from sim.vehicle.copter import Copter, CopterConfig
from sim.vehicle.standalone import OpenPad
from sim.vehicle.streams import HEARTBEAT, build

MAV_STATE_CRITICAL, MAV_STATE_ACTIVE = 5, 4


@pytest.mark.parametrize(
    ("action", "continue_landing", "flying", "then"),
    [
        ("none", True, GUIDED, GUIDED),  # ArduPilot's default: a warning, no mode of its own
        ("land", True, GUIDED, LAND),
        ("rtl", True, GUIDED, RTL),
        ("rtl", True, LAND, LAND),  # the landing goes on
        ("rtl", False, LAND, RTL),  # without CONTINUE_IF_LANDING it returns home from LAND
        ("none", True, LAND, LAND),
    ],
)
def test_a_low_battery_in_flight_is_critical_and_takes_its_action(
    action: str, continue_landing: bool, flying: int, then: int
) -> None:
    config = CopterConfig(
        seed=2, failsafe_battery_action=action, failsafe_continue_landing=continue_landing
    )  # type: ignore[arg-type]
    c = Copter(OpenPad(), config)
    assert c.set_mode(GUIDED) and c.arm() == 0 and c.guidance.takeoff(8) == 0
    while c.dyn.state.altitude < 7.5 and c.t < 30.0:
        c.tick(0.05, 0.0)
    assert c.set_mode(flying)
    c.tick(0.05, 0.0)
    assert build(c, HEARTBEAT).system_status == MAV_STATE_ACTIVE
    c.dyn.set_battery(14.0)
    c.tick(0.05, 0.0)
    assert c.failsafe and c.mode == then
    assert build(c, HEARTBEAT).system_status == MAV_STATE_CRITICAL
    texts = [m.text for _, m in c.outbox if m.get_type() == "STATUSTEXT"]
    assert "Battery Failsafe" in texts
