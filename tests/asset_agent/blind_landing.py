"""Shared by the precision-landing daemon tests against the simulated autopilot: an adapter
streaming what precision landing needs, the daemon's lander fed by an IR beacon that runs (so the
landing loop starts) with every reading dropped, a take-off to 11 m followed by LAND, and the
vehicle's lowest altitude meanwhile."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.config import DEFAULT_STREAMS
from asset_agent.config import PreclandSection
from asset_agent.precland.config import FaultConfig
from asset_agent.precland.resume import Memory
from asset_agent.precland.supervisor import PrecisionLander, stream_rates
from asynckit.tasks import cancel_and_wait
from sim.ir import IrBeaconSensor
from sim.vehicle.server import VehicleServer
from tests.asset_agent.conftest import fast_config
from tests.polling import eventually


def precland_streams() -> dict[int, float]:
    """The streams the daemon asks for with precision landing on (msg id -> Hz)."""
    return {**DEFAULT_STREAMS, **stream_rates(PreclandSection())}


@contextlib.asynccontextmanager
async def precland_adapter(vehicle: VehicleServer) -> AsyncIterator[Autopilot]:
    """An adapter streaming what precision landing needs, as the daemon asks for it."""
    streams = precland_streams()
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
async def blind_beacon_lander(
    ap: Autopilot,
    vehicle: VehicleServer,
    /,
    fault: FaultConfig | None = None,
    memory: Memory | None = None,
    **section: Any,
) -> AsyncIterator[PrecisionLander]:
    """The daemon's precision landing (`PreclandSection(**section)`, its state file `memory`)
    with an IR beacon whose every reading is dropped (or those `fault` drops): the loop runs, it
    never sees the pad."""
    copter = vehicle.copter

    def pose() -> tuple[float, float, float, float, float, float]:
        st = copter.dyn.state
        n, e, d = st.position
        return (n, e, 0.25 - d, st.roll, st.pitch, st.yaw)

    beacon = IrBeaconSensor(pose, vehicle.clock)
    port = await beacon.start()
    lander = PrecisionLander(
        ap,
        PreclandSection(ir_port=port, faults={"ir": fault or FaultConfig(r_drop=1.0)}, **section),
        memory,
    )
    stop = asyncio.Event()
    task = asyncio.create_task(lander.run(stop))
    try:
        yield lander
    finally:
        stop.set()
        await task
        await beacon.stop()


async def take_off_and_land(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    """GUIDED, arm, take off to 11 m, then LAND."""
    await autopilot.set_mode("GUIDED")
    await autopilot.arm()
    await autopilot.takeoff(11)
    await eventually(lambda: vehicle.copter.dyn.state.altitude > 10.5, 20, "takeoff")
    await autopilot.land()


@contextlib.asynccontextmanager
async def lowest_altitude(vehicle: VehicleServer) -> AsyncIterator[list[float]]:
    """The vehicle's lowest altitude while the block runs (as the simulator knows it), once
    it has climbed above 5 m."""
    lowest: list[float] = []

    async def watch() -> None:
        while True:
            alt = vehicle.copter.dyn.state.altitude
            if lowest or alt > 5.0:
                lowest[:] = [min(lowest[0], alt) if lowest else alt]
            await asyncio.sleep(0.01)

    task = asyncio.create_task(watch())
    try:
        yield lowest
    finally:
        await cancel_and_wait([task])
