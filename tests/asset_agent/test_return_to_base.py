"""ReturnToBase once the mission's own return-home has the UAV (issue 14 #6: the agent owns the
landing; the server asks for the return when its link comes back, after the fact).

Against the simulated autopilot over MAVLink (UDP), through the agent's real command handler.
"""

from __future__ import annotations

import uuid

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.availability import AvailabilityLimits
from asset_agent.handlers import Handlers
from assetlink.dispatch import CommandRequest
from protocol.vocabulary import MissionItem, ReturnToBase, UploadMission
from sim.vehicle.constants import AUTO, RTL
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.server import VehicleServer
from sim.vehicle.standalone import OpenPad
from tests.polling import eventually

pytestmark = pytest.mark.slow  # a whole (20x) flight


def _mission(pad: OpenPad) -> UploadMission:
    lat, lon = GeoOrigin(*pad.pad_geodetic).to_geodetic(30.0, 0.0, 0.0)[:2]
    items = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 12},
        {"command": 16, "frame": 3, "params": [0, 0, 0, 0], "lat": lat, "lon": lon, "alt": 12},
        {"command": 20, "frame": 2, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0},
    ]
    return UploadMission(items=tuple(MissionItem.model_validate(i) for i in items))


async def _answer(handler, command):  # type: ignore[no-untyped-def]
    output = handler(CommandRequest(uuid.uuid4(), command))
    if hasattr(output, "__aiter__"):
        return [item async for item in output][-1]
    return await output


async def test_return_to_base_leaves_the_missions_own_return_and_a_landed_uav_alone(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    handlers = Handlers(autopilot, AvailabilityLimits(min_battery_pct=0.0, min_fix_type=0))
    table = handlers.table()
    uploaded = await _answer(table[UploadMission], _mission(pad))
    assert uploaded.status == "succeeded", uploaded
    await autopilot.start_mission()
    copter = vehicle.copter
    await eventually(lambda: autopilot.state.mission_current == 2, 60, "the mission's return-home")
    await eventually(lambda: autopilot.state.mode == "AUTO" and autopilot.state.armed, 5, "AUTO")
    # the link comes back while the mission brings the UAV home: it is left to do so
    on_the_way = await _answer(table[ReturnToBase], ReturnToBase())
    assert on_the_way.status == "succeeded", on_the_way
    assert "already returning" in on_the_way.reason and on_the_way.data == {"action": "none"}
    assert copter.mode == AUTO  # no RTL restarted: no climb back for a second approach
    await eventually(lambda: not autopilot.state.armed, 60, "landed and disarmed")
    await eventually(lambda: autopilot.state.landed_state == "ON_GROUND", 5, "ON_GROUND")
    # ...or once it has landed: nothing to return from, the autopilot is not left in RTL
    landed = await _answer(table[ReturnToBase], ReturnToBase())
    assert landed.status == "succeeded" and "already landed" in landed.reason, landed
    assert copter.mode != RTL


async def test_return_to_base_still_returns_a_uav_that_is_not_on_its_way(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    handlers = Handlers(autopilot, AvailabilityLimits(min_battery_pct=0.0, min_fix_type=0))
    await autopilot.set_mode("GUIDED")
    await autopilot.arm()
    await autopilot.takeoff(8.0)
    await eventually(lambda: vehicle.copter.dyn.state.altitude > 6, 30, "climb")
    await eventually(lambda: autopilot.state.armed and autopilot.state.in_air, 5, "seen flying")
    answer = await _answer(handlers.table()[ReturnToBase], ReturnToBase())
    assert answer.status == "succeeded", answer
    await eventually(lambda: vehicle.copter.mode == RTL, 5, "RTL")
