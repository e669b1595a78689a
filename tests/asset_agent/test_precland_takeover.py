"""The daemon's search before the autopilot's own descent (takeover.py), against the simulated
autopilot over MAVLink and the simulated IR beacon over UDP: a landing whose pad is never seen is
searched for, then abandoned by a climb on a plain fix, or landed on the RTK fixed GNSS."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.config import DEFAULT_STREAMS
from asset_agent.config import PreclandSection
from asset_agent.precland.config import FaultConfig, SearchConfig
from asset_agent.precland.supervisor import PrecisionLander, stream_rates
from sim.ir import IrBeaconSensor
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.conftest import fast_config
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
    """An adapter streaming what precision landing needs, as the daemon asks for it."""
    streams = {**DEFAULT_STREAMS, **stream_rates(PreclandSection())}
    ap = Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}", streams=streams))
    await ap.start()
    try:
        await ap.wait_link(10)
        await asyncio.wait_for(ap.streams_requested.wait(), 10)
        await eventually(lambda: ap.state.lat is not None and ap.state.home_lat is not None, 10)
        yield ap
    finally:
        await ap.close()


@contextlib.asynccontextmanager
async def lander_with_a_blind_beacon(autopilot: Autopilot, vehicle: VehicleServer):
    """The daemon's precision landing fed by an IR beacon whose every reading is dropped (the
    sensor runs, so the landing loop does; it never sees the pad)."""
    copter = vehicle.copter

    def pose():
        st = copter.dyn.state
        n, e, d = st.position
        return (n, e, 0.25 - d, st.roll, st.pitch, st.yaw)

    beacon = IrBeaconSensor(pose, vehicle.clock)
    port = await beacon.start()
    section = PreclandSection(
        ir_port=port, search=SEARCH, faults={"ir": FaultConfig(r_drop=1.0)}, pad_sigma_m=0.5
    )
    lander = PrecisionLander(autopilot, section)
    stop = asyncio.Event()
    task = asyncio.create_task(lander.run(stop))
    try:
        yield lander
    finally:
        stop.set()
        await task
        await beacon.stop()


async def take_off_and_land(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    await autopilot.set_mode("GUIDED")
    await autopilot.arm()
    await autopilot.takeoff(11)
    await eventually(lambda: vehicle.copter.dyn.state.altitude > 10.5, 20, "takeoff")
    await autopilot.land()


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
