"""The daemon's landing loop starts only once it knows where the pad is (the survey, or home),
against the simulated autopilot over MAVLink: an agent that has not heard HOME_POSITION yet (just
started, or restarted in flight) would otherwise search around, and on an RTK fix fall back onto,
its own position."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.streams import (
    CMD_GET_HOME_POSITION,
    CMD_SET_MESSAGE_INTERVAL,
    HOME_POSITION,
)
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.blind_landing import (
    blind_beacon_lander,
    precland_streams,
    take_off_and_land,
)
from tests.asset_agent.conftest import fast_config
from tests.asset_agent.test_precland_takeover import SEARCH
from tests.polling import eventually


@pytest.fixture
async def vehicle() -> AsyncIterator[VehicleServer]:
    async with run_vehicle(speed=4.0, seed=7) as server:
        yield server


def adapter(vehicle: VehicleServer) -> Autopilot:
    """An adapter that never asks for HOME_POSITION."""
    streams = precland_streams()
    del streams[HOME_POSITION]
    return Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}", streams=streams))


async def test_the_landing_loop_waits_for_the_pads_position(vehicle: VehicleServer) -> None:
    """The agent starts (or restarts) with the vehicle already landing: ArduPilot sends
    HOME_POSITION when home is set, at arming, and then only as asked (here: never)."""
    first = adapter(vehicle)
    await first.start()
    await first.wait_link(10)
    await eventually(lambda: first.state.lat is not None, 10, "a position")
    await first.command(CMD_SET_MESSAGE_INTERVAL, HOME_POSITION, -1)  # the simulator's default
    await take_off_and_land(first, vehicle)
    await first.close()
    autopilot = adapter(vehicle)
    await autopilot.start()
    try:
        await autopilot.wait_link(10)
        await landing_without_home(autopilot, vehicle)
    finally:
        await autopilot.close()


async def landing_without_home(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    async with blind_beacon_lander(autopilot, vehicle, search=SEARCH, pad_sigma_m=0.5) as lander:
        await eventually(lambda: lander.ready, 10, "the sensors' clock and the position")
        # in LAND from above the activation height (10 m) down to 6 m: a loop would have started
        # (and this ends the wait at once, to fail below)
        await eventually(
            lambda: (autopilot.state.alt_rel or 99.0) < 6.0 or lander.stats.landings,
            15,
            "LAND down to 6 m",
        )
        assert autopilot.state.mode == "LAND" and autopilot.state.home_lat is None
        assert lander.stats.landings == 0 and lander.takeover is None  # no pad: no loop
        await autopilot.command(CMD_GET_HOME_POSITION)
        await eventually(lambda: lander.stats.landings, 5, "the loop, once home is known")
        assert lander.loop is not None and lander.loop.pipeline.kalman.initialised
