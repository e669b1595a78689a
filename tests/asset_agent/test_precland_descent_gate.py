"""The daemon asks the autopilot's own LAND to descend only while over the contacts: it sets
ArduPilot's PLND_XY_DIST_MAX over MAVLink when a landing starts (`[precland.autopilot]`), relaxes
it when the landing has lasted too long, and lands as before on an autopilot without it. Against
the simulated autopilot (ArduPilot 4 with PLND, which applies the parameter to its LAND)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator
from dataclasses import replace

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.precland.config import AutopilotDescentConfig, SearchConfig
from asset_agent.precland.resume import Memory
from sim.vehicle.copter import CopterConfig
from sim.vehicle.habits import profile
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.blind_landing import (
    blind_beacon_lander,
    precland_adapter,
    take_off_and_land,
)
from tests.polling import eventually

SPEED = 4.0  # the landing at 4x: its HEARTBEATs come once a wall second
PLND = replace(profile("ardupilot-4"), streams_at_boot="all", boot_s=0.0)


@contextlib.asynccontextmanager
async def flying(habits) -> AsyncIterator[tuple[VehicleServer, Autopilot]]:
    async with (
        run_vehicle(speed=SPEED, config=CopterConfig(seed=3, habits=habits)) as vehicle,
        precland_adapter(vehicle) as ap,
    ):
        yield vehicle, ap


def lander(
    ap: Autopilot,
    vehicle: VehicleServer,
    gate: AutopilotDescentConfig,
    memory: Memory | None = None,
):
    """The daemon's precision landing, mode landing_target, its beacon blind; no search, so the
    autopilot keeps LAND (its state file `memory`)."""
    return blind_beacon_lander(
        ap, vehicle, search=SearchConfig(enabled=False), autopilot=gate, memory=memory
    )


def test_the_gate_is_the_configured_radius_until_the_landing_is_too_old() -> None:
    gate = AutopilotDescentConfig(xy_dist_max_m=0.05, relax_after_s=180, relaxed_xy_dist_max_m=2.5)
    assert gate.xy_dist_max_at(0) == 0.05 and gate.xy_dist_max_at(179.9) == 0.05
    assert gate.xy_dist_max_at(180) == 2.5
    assert AutopilotDescentConfig(xy_dist_max_m=None).xy_dist_max_at(0) is None


async def test_a_landing_sets_plnd_xy_dist_max_over_mavlink_and_relaxes_it_late() -> None:
    gate = AutopilotDescentConfig(xy_dist_max_m=0.05, relax_after_s=6.0, relaxed_xy_dist_max_m=2.5)
    async with flying(PLND) as (vehicle, ap), lander(ap, vehicle, gate) as daemon:
        copter = vehicle.copter
        assert copter.param("PLND_XY_DIST_MAX") == 2.5  # ArduPilot's default
        await take_off_and_land(ap, vehicle)
        await eventually(lambda: daemon.xy_dist_max == pytest.approx(0.05), 20, "the gate set")
        # the autopilot answered with the value it holds (a float32), and its LAND flies by it
        assert copter.param("PLND_XY_DIST_MAX") == pytest.approx(0.05)
        await eventually(  # its next loop reads it
            lambda: copter.plnd.p.xy_dist_max == pytest.approx(0.05), 5, "PLND reads it"
        )
        assert copter.flying
        # six sensor seconds later the landing is "too old": ArduPilot's default again
        await eventually(lambda: daemon.xy_dist_max == 2.5, 20, "the gate relaxed")
        await eventually(lambda: copter.plnd.p.xy_dist_max == 2.5, 5, "PLND reads it")
        await eventually(lambda: not ap.state.armed, 90, "landed and disarmed")


@pytest.mark.slow  # ~10 s: the parameter set is retried on silence before the daemon gives up
async def test_an_autopilot_without_the_parameter_still_lands(caplog) -> None:
    """ArduPilot 3.7 (no PLND_XY_DIST_MAX: it answers nothing): the daemon asks, gives up with a
    warning, and the autopilot lands as before; the next landing does not ask again."""
    caplog.set_level(logging.INFO, logger="asset_agent.precland.supervisor")
    caplog.set_level(logging.INFO, logger="asset_agent.precland.readiness")  # the gate's
    old = profile("ardupilot-3.7")
    habits = replace(old, streams_at_boot="all", boot_s=0.0)
    gate = AutopilotDescentConfig(xy_dist_max_m=0.05)
    async with flying(habits) as (vehicle, ap), lander(ap, vehicle, gate) as daemon:
        await take_off_and_land(ap, vehicle)
        await eventually(lambda: daemon.loop is not None, 30, "the landing loop")
        await eventually(
            lambda: "PLND_XY_DIST_MAX not set" in caplog.text, 30, "the daemon to give up asking"
        )
        await eventually(lambda: not ap.state.armed, 90, "landed and disarmed")
        assert daemon.xy_dist_max is None
        assert "PLND_XY_DIST_MAX" not in vehicle.copter.fence.params
        landings = daemon.stats.landings
        await take_off_and_land(ap, vehicle)
        await eventually(lambda: daemon.stats.landings > landings, 30, "the next landing")
        await eventually(lambda: "has no PLND_XY_DIST_MAX" in caplog.text, 5, "the gate skipped")
        assert caplog.text.count("PLND_XY_DIST_MAX not set") == 1
        await eventually(lambda: not ap.state.armed, 90, "landed and disarmed again")
