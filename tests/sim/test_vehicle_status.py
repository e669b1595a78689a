"""The simulated autopilot's HEARTBEAT system_status, as ArduCopter's vehicle_system_status:
STANDBY while its land detector says landed, armed or not; ACTIVE in the air. (It said ACTIVE
whenever armed: an ArduPilot 3.x agent, which infers the landed state from it, read an armed
copter on the ground as possibly flying.)"""

from __future__ import annotations

from sim.vehicle.constants import GUIDED, LAND
from sim.vehicle.copter import Copter, CopterConfig
from sim.vehicle.standalone import OpenPad
from sim.vehicle.streams import HEARTBEAT, build

MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4


def status(c: Copter) -> int:
    return int(build(c, HEARTBEAT).system_status)


def test_standby_on_the_ground_armed_or_not_active_in_the_air() -> None:
    c = Copter(OpenPad(), CopterConfig(seed=2))
    assert status(c) == MAV_STATE_STANDBY  # disarmed on the pad
    assert c.set_mode(GUIDED) and c.arm() == 0
    c.tick(0.05, 0.0)
    assert c.armed and status(c) == MAV_STATE_STANDBY  # armed, not taken off
    assert c.guidance.takeoff(5) == 0
    while c.dyn.state.altitude < 4.5 and c.t < 30.0:
        c.tick(0.05, 0.0)
    assert status(c) == MAV_STATE_ACTIVE
    assert c.set_mode(LAND)
    while not c.guidance.land_complete and c.t < 90.0:
        c.tick(0.05, 0.0)
        if c.armed and not c.guidance.land_complete:
            assert status(c) == MAV_STATE_ACTIVE  # descending
    assert c.guidance.land_complete  # touched down (LAND disarms at once)
    assert status(c) == MAV_STATE_STANDBY
