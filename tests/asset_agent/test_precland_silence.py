"""Precision landing that sends no LANDING_TARGET for 2 s while its sensors' readings arrive says
so at once, and its `landed` event says how it came down (issue 46)."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.events import Event
from asset_agent.precland.config import SearchConfig
from asset_agent.precland.silence import SilenceWatch
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.asset_agent.blind_landing import blind_beacon_lander, precland_adapter, take_off_and_land
from tests.polling import eventually


@pytest.fixture
async def vehicle() -> AsyncIterator[VehicleServer]:
    async with run_vehicle(speed=4.0, seed=11) as server:
        yield server


@pytest.fixture
async def autopilot(vehicle: VehicleServer) -> AsyncIterator[Autopilot]:
    async with precland_adapter(vehicle) as ap:
        yield ap


async def test_a_landing_that_sends_nothing_while_readings_arrive_warns_at_once(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    """The IR beacon's readings arrive and every one is dropped (no search: the autopilot lands
    by itself): within 2 s of wall time of the loop starting, still in the air, the warning."""
    no_search = SearchConfig(enabled=False)
    async with blind_beacon_lander(autopilot, vehicle, search=no_search) as lander:
        await take_off_and_land(autopilot, vehicle)
        await eventually(lambda: lander.loop is not None, 30, "the landing loop to start")
        started = time.monotonic()
        warned: list[Event] = []

        def heard() -> bool:
            warned.extend(e for e in lander.drain_events() if e.kind == "precland_silent")
            return bool(warned)

        await eventually(heard, 10, "the silence warning")
        took = time.monotonic() - started
        assert 2.0 <= took < 3.0, took  # at once: the watch looks every 50 ms
        assert vehicle.copter.dyn.state.altitude > 1.0  # before it lands, not after
        detail = warned[0].detail
        assert detail["targets_sent"] == 0 and detail["ir_readings"] > 10, detail
        await eventually(lambda: not vehicle.copter.armed, 60, "the landing")
        # the landed event tells a landing the sensors watched and did not steer
        told = lander.touchdown_offset()
        assert told["landing_path"] == "gnss", told
        assert told["precland_targets"] == 0 and told["precland_warnings"] == 1, told
        assert told["precland_ir_readings"] > 10, told
        blind = lander.silence.blind_landing(told["landing_path"])  # sent after `landed`
        assert blind is not None and blind.kind == "landed_without_precision", blind


def test_one_warning_per_silence_and_none_while_targets_go_out() -> None:
    wall = [0.0]
    watch = SilenceWatch(window_s=2.0, wall=lambda: wall[0])
    watch.start()
    for _ in range(40):  # readings and a target every 0.1 s: never silent
        watch.reading("camera")
        watch.sent()
        wall[0] += 0.1
        assert watch.check() is None
    for _ in range(18):  # up to 1.9 s of readings and no target: not yet
        watch.reading("camera")
        wall[0] += 0.1
        assert watch.check() is None
    watch.reading("camera")
    wall[0] += 0.2
    first = watch.check(clock_epochs=1)
    assert first is not None and first.kind == "precland_silent"
    assert first.detail["clock_epochs"] == 1 and first.detail["silent_s"] == 2.1
    wall[0] += 5.0
    watch.reading("ir")
    assert watch.check() is None  # told once for this silence
    watch.sent()  # a target: the silence is over; the next one is told again
    for _ in range(21):
        watch.reading("ir")
        wall[0] += 0.1
    assert watch.check() is not None and watch.warnings == 2


def test_no_warning_when_no_reading_arrives_or_the_agent_searches() -> None:
    wall = [0.0]
    watch = SilenceWatch(window_s=2.0, wall=lambda: wall[0])
    watch.start()
    wall[0] += 5.0
    assert watch.check() is None  # nothing arrives: the sensors are gone, not the landing
    for _ in range(30):
        watch.reading("camera")
        wall[0] += 0.1
        assert watch.check(searching=True) is None  # the agent flies the search itself
