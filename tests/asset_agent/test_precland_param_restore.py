"""Every autopilot parameter the agent changes for a landing reads back as before once the
landing is over (restore.py): after a precision landing, and after an agent stopped in the
middle of one and started again on its state file. Against the simulated autopilot, which keeps
a PARAM_SET through a reboot as ArduPilot saves it; every parameter read over MAVLink."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.params import read_param, set_param
from asset_agent.precland.config import AutopilotDescentConfig
from asset_agent.precland.restore import KEY
from asset_agent.precland.supervisor import PrecisionLander
from sim.vehicle.server import VehicleServer
from tests.asset_agent.blind_landing import blind_beacon_lander, take_off_and_land
from tests.asset_agent.test_precland_descent_gate import PLND, flying, lander
from tests.asset_agent.test_precland_takeover import SEARCH, state_file
from tests.polling import eventually

# the contacts' 5 cm, never relaxed within these landings
GATE = AutopilotDescentConfig(xy_dist_max_m=0.05, relax_after_s=600.0)


async def every_param(ap: Autopilot, vehicle: VehicleServer) -> dict[str, float]:
    """Each parameter the simulated autopilot has, as it answers PARAM_REQUEST_READ."""
    return {name: await read_param(ap, name) for name in list(vehicle.copter.fence.params)}


async def watch_while_flying(vehicle: VehicleServer, seen: list[float]) -> None:
    """PLND_XY_DIST_MAX as the autopilot holds it, each step it flies."""
    while True:
        if vehicle.copter.flying:
            seen.append(vehicle.copter.param("PLND_XY_DIST_MAX"))
        await asyncio.sleep(0.01)


async def restored(vehicle: VehicleServer, daemon: PrecisionLander) -> None:
    """Until the autopilot holds ArduPilot's default PLND_XY_DIST_MAX again and the daemon's
    restore is over (its record forgotten)."""
    await eventually(lambda: vehicle.copter.param("PLND_XY_DIST_MAX") == 2.5, 20, "restored")
    await eventually(lambda: daemon.params.settled, 5, "the restore over")


async def landed(ap: Autopilot) -> None:
    await eventually(lambda: not ap.state.armed, 90, "landed and disarmed")


async def test_a_parameter_set_survives_a_reboot_of_the_simulated_autopilot() -> None:
    """ArduPilot's PARAM_SET saves to storage (AP_Param::set_and_save): a reboot keeps it."""
    async with flying(PLND) as (vehicle, ap):
        await set_param(ap, "PLND_XY_DIST_MAX", 0.05)
        boots = vehicle.copter.boots
        await ap.reboot()
        await eventually(lambda: vehicle.copter.boots > boots, 20, "rebooted")
        await ap.wait_link(10)
        assert await read_param(ap, "PLND_XY_DIST_MAX") == pytest.approx(0.05)


async def test_after_a_precision_landing_every_parameter_reads_back_as_before(
    tmp_path: Path,
) -> None:
    async with flying(PLND) as (vehicle, ap), state_file(tmp_path / "agent.db") as memory:
        before = await every_param(ap, vehicle)
        assert before["PLND_XY_DIST_MAX"] == 2.5  # ArduPilot's default
        async with lander(ap, vehicle, GATE, memory=memory) as daemon:
            seen: list[float] = []
            watch = asyncio.create_task(watch_while_flying(vehicle, seen))
            await take_off_and_land(ap, vehicle)
            await eventually(lambda: daemon.xy_dist_max == pytest.approx(0.05), 20, "the gate")
            assert await memory.recall(KEY) is not None  # kept before it was set
            await landed(ap)
            await restored(vehicle, daemon)
            watch.cancel()
        assert await every_param(ap, vehicle) == before
        assert await memory.recall(KEY) is None
        # the landing flew by the gate to the ground: no restore under it
        assert seen and seen[-1] == pytest.approx(0.05)


async def test_an_agent_stopped_mid_landing_and_restarted_restores_after_the_landing(
    tmp_path: Path,
) -> None:
    """Stopped with PLND_XY_DIST_MAX at 0.05 m, the agent leaves it (the autopilot lands on by
    it); the next one, started while the vehicle still descends, keeps it there until the
    vehicle is down, then gives the value from before back."""
    async with flying(PLND) as (vehicle, ap), state_file(tmp_path / "agent.db") as memory:
        before = await every_param(ap, vehicle)
        async with lander(ap, vehicle, GATE, memory=memory) as first:
            await take_off_and_land(ap, vehicle)
            await eventually(lambda: first.xy_dist_max == pytest.approx(0.05), 20, "the gate")
        assert vehicle.copter.flying  # stopped in the middle of the landing
        assert await read_param(ap, "PLND_XY_DIST_MAX") == pytest.approx(0.05)
        seen: list[float] = []
        watch = asyncio.create_task(watch_while_flying(vehicle, seen))
        async with lander(ap, vehicle, GATE, memory=memory) as second:
            assert vehicle.copter.flying
            await landed(ap)
            await restored(vehicle, second)
            watch.cancel()
        assert await every_param(ap, vehicle) == before
        assert await memory.recall(KEY) is None
        assert seen and all(v == pytest.approx(0.05) for v in seen)  # never under the landing


async def test_a_record_left_by_an_agent_is_restored_by_the_next_on_the_ground(
    tmp_path: Path,
) -> None:
    """The vehicle landed after its agent stopped: the next agent restores at start."""
    async with flying(PLND) as (vehicle, ap), state_file(tmp_path / "agent.db") as memory:
        before = await every_param(ap, vehicle)
        async with lander(ap, vehicle, GATE, memory=memory) as first:
            await take_off_and_land(ap, vehicle)
            await eventually(lambda: first.xy_dist_max == pytest.approx(0.05), 20, "the gate")
        await landed(ap)
        assert await read_param(ap, "PLND_XY_DIST_MAX") == pytest.approx(0.05)  # left so
        async with lander(ap, vehicle, GATE, memory=memory) as second:
            await restored(vehicle, second)
        assert await every_param(ap, vehicle) == before


async def test_an_abandoned_landing_gives_the_parameter_back_in_its_hold() -> None:
    """No pad found on a plain fix: the landing is abandoned and the vehicle holds at its safe
    height for the operator; the landing's parameter is given back there."""
    async with flying(PLND) as (vehicle, ap):
        before = await every_param(ap, vehicle)
        async with blind_beacon_lander(
            ap, vehicle, search=SEARCH, pad_sigma_m=0.5, autopilot=GATE
        ) as daemon:
            await take_off_and_land(ap, vehicle)
            await eventually(lambda: daemon.xy_dist_max == pytest.approx(0.05), 20, "the gate")
            await eventually(lambda: daemon.takeover and daemon.takeover.path, 40, "its end")
            assert daemon.takeover is not None and daemon.takeover.path == "aborted-climb"
            await restored(vehicle, daemon)
            assert ap.state.mode == "GUIDED" and vehicle.copter.flying  # in the hold
            assert await every_param(ap, vehicle) == before
