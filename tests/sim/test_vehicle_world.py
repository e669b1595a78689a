"""The vehicle in the whole world: it leaves only an open base and lands back on its scale and contacts."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from asset_agent.autopilot import Autopilot, AutopilotConfig, CommandRejected
from protocol.rtcm import build_frame
from sim.plc.model import LIFT_UP, PANELS_OPEN
from sim.vehicle.part import VehiclePart
from sim.world import World, WorldConfig
from tests.polling import eventually


@pytest.mark.slow
async def test_leave_the_open_base_and_land_back_on_the_pad() -> None:
    world = World(WorldConfig.for_tests(speed=20.0, seed=11))
    part = VehiclePart()
    world.add_part(part)
    async with world:
        base, copter = world.base, part.server.copter  # type: ignore[union-attr]
        mass = copter.config.dynamics.mass_g
        assert base.pad_mass_g == mass and base.contacts_seated
        ap = Autopilot(
            AutopilotConfig(
                url=f"udpout:127.0.0.1:{world.ports['mavlink_udp']}", link_timeout_s=2.0
            )
        )
        await ap.start()

        async def corrections() -> None:
            while True:
                ap.inject_rtcm(build_frame(bytes([0x3E, 0xD0]) + bytes(17)))
                await asyncio.sleep(0.2)

        feeder = asyncio.create_task(corrections())
        try:
            await ap.wait_link(10)
            await eventually(lambda: ap.state.fix_type == 6, 15, "RTK fixed")
            await ap.set_mode("GUIDED")
            try:
                await ap.arm()
                raise AssertionError("armed inside a closed base")
            except CommandRejected as err:
                assert "Base closed" in err.detail
            base.write_coils(PANELS_OPEN, [True])
            await eventually(
                lambda: base.panels.at_high and not base.panels.moving, 20, "panels open"
            )
            base.write_coils(LIFT_UP, [True])
            await eventually(base.can_vehicle_leave, 20, "lift up")
            await ap.arm()
            await ap.takeoff(6)
            await eventually(lambda: copter.dyn.state.altitude > 5.5, 20, "took off")
            assert base.pad_mass_g == 0 and not base.contacts_seated
            await ap.return_to_base()
            await eventually(lambda: not copter.armed, 60, "landed and disarmed")
        finally:
            feeder.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await feeder
            await ap.close()
        dist = copter.pad_distance()
        assert dist < 0.3, f"landed {dist:.3f} m off the pad centre in the world's wind"
        assert base.pad_mass_g == mass
        assert base.contacts_seated == (dist <= copter.config.contacts_tolerance_m)
