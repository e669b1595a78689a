"""The daemon's landing loop starts only once it knows where the pad is (the survey, or home),
against the simulated autopilot over MAVLink: an agent that has not heard HOME_POSITION yet (just
started, or restarted in flight) would otherwise search around, and on an RTK fix fall back onto,
its own position."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.config import DEFAULT_STREAMS
from asset_agent.autopilot.streams import CMD_GET_HOME_POSITION, HOME_POSITION
from asset_agent.config import PreclandSection
from asset_agent.precland.supervisor import stream_rates
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.blind_landing import blind_beacon_lander, take_off_and_land
from tests.asset_agent.conftest import fast_config
from tests.asset_agent.test_precland_takeover import SEARCH
from tests.polling import eventually


@pytest.fixture
async def vehicle() -> AsyncIterator[VehicleServer]:
    async with run_vehicle(speed=4.0, seed=7) as server:
        yield server


@pytest.fixture
async def autopilot(vehicle: VehicleServer) -> AsyncIterator[Autopilot]:
    """An adapter that never asks for HOME_POSITION: home stays unknown until the test asks."""
    streams = {**DEFAULT_STREAMS, **stream_rates(PreclandSection())}
    del streams[HOME_POSITION]
    ap = Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}", streams=streams))
    await ap.start()
    try:
        await ap.wait_link(10)
        await eventually(lambda: ap.state.lat is not None, 10, "a position")
        yield ap
    finally:
        await ap.close()


async def test_the_landing_loop_waits_for_the_pads_position(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    async with blind_beacon_lander(autopilot, vehicle, search=SEARCH, pad_sigma_m=0.5) as lander:
        await take_off_and_land(autopilot, vehicle)
        # (or a loop started without the pad's position, which this test is to catch)
        await eventually(
            lambda: (
                (autopilot.state.mode == "LAND" and autopilot.state.alt_rel < 9.5)
                or lander.stats.landings
            ),
            10,
            "LAND below the activation height",
        )
        assert autopilot.state.home_lat is None
        assert lander.stats.landings == 0 and lander.takeover is None  # no pad: no loop
        await autopilot.command(CMD_GET_HOME_POSITION)
        await eventually(lambda: lander.stats.landings, 5, "the loop, once home is known")
        assert lander.loop is not None and lander.loop.pipeline.kalman.initialised
