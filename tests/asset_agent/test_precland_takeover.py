"""The daemon's search before the autopilot's own descent (takeover.py), against the simulated
autopilot over MAVLink and the simulated IR beacon over UDP: a landing whose pad is never seen is
searched for, then abandoned by a climb on a plain fix, or landed on the RTK fixed GNSS."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.precland.config import SearchConfig
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.blind_landing import (
    blind_beacon_lander,
    precland_adapter,
    take_off_and_land,
)
from tests.asset_agent.test_autopilot_flight import corrections
from tests.polling import eventually

SEARCH = SearchConfig(acquire_s=1.0, max_radius_m=3.0, max_time_s=8.0, abort_height_m=13.0)


@pytest.fixture
async def vehicle() -> AsyncIterator[VehicleServer]:
    """The simulated autopilot at 4x: its HEARTBEAT (the mode) comes once a wall second, so
    faster the landing would be over before the daemon sees it begin."""
    async with run_vehicle(speed=4.0, seed=7) as server:
        yield server


@pytest.fixture
async def autopilot(vehicle: VehicleServer) -> AsyncIterator[Autopilot]:
    async with precland_adapter(vehicle) as ap:
        yield ap


def lander_with_a_blind_beacon(autopilot: Autopilot, vehicle: VehicleServer):
    """The daemon's precision landing searching with SEARCH, its beacon blind."""
    return blind_beacon_lander(autopilot, vehicle, search=SEARCH, pad_sigma_m=0.5)


async def test_no_pad_found_on_a_plain_fix_climbs_to_a_safe_height_and_reports(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    async with lander_with_a_blind_beacon(autopilot, vehicle) as lander:
        await take_off_and_land(autopilot, vehicle)
        await eventually(lambda: autopilot.state.mode == "GUIDED", 20, "the agent takes over")
        assert vehicle.copter.dyn.state.altitude > 5  # it did not land on GNSS alone
        await eventually(lambda: lander.takeover and lander.takeover.path, 30, "the search's end")
        assert lander.takeover is not None and lander.takeover.path == "aborted-climb"
        assert vehicle.copter.dyn.state.altitude > 10.5 and vehicle.copter.armed
        events = lander.drain_events()
        assert [e.kind for e in events] == ["landing_aborted"]
        assert events[0].detail["landing_path"] == "aborted-climb"


@pytest.mark.slow  # ~10 s: the landing from 10 m at 4x
async def test_no_pad_found_on_rtk_fixed_lands_on_the_gnss_over_the_surveyed_pad(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    async with (
        corrections(autopilot, 0.1),
        lander_with_a_blind_beacon(autopilot, vehicle) as lander,
    ):
        await eventually(lambda: autopilot.state.fix_type == 6, 15, "RTK fixed")
        await take_off_and_land(autopilot, vehicle)
        await eventually(lambda: autopilot.state.mode == "GUIDED", 20, "the agent takes over")
        await eventually(lambda: not autopilot.state.armed, 60, "landed and disarmed")
        assert lander.takeover is not None and lander.takeover.path == "rtk-fallback"
        assert vehicle.copter.pad_distance() < 0.3  # on its RTK GNSS, home surveyed on it
        assert lander.touchdown_offset()["landing_path"] == "rtk-fallback"
