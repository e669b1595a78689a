"""The daemon entry point: setup / run / main, driven in-process against the simulator."""

from __future__ import annotations

import asyncio
from pathlib import Path

from bs_helpers import station_config

from base_station.main import main, run, setup
from sim.world import World, WorldConfig
from tests.polling import eventually


def test_main_with_a_missing_config_exits_2(tmp_path: Path) -> None:
    assert main(["--config", str(tmp_path / "nope.toml")]) == 2


def test_main_with_an_invalid_config_exits_2(tmp_path: Path) -> None:
    f = tmp_path / "base.toml"
    f.write_text("[plc]\npoll_hz = 1\n")
    assert main(["--config", str(f)]) == 2


async def test_run_connects_reads_and_stops_cleanly_without_writing_commands() -> None:
    async with World(WorldConfig.for_tests(speed=10.0, seed=2)) as world:
        app = setup(station_config(world.ports["plc"]))
        stop = asyncio.Event()
        linked: list[str] = []

        async def link(station, config) -> None:  # type: ignore[no-untyped-def]
            linked.append(station.telemetry().plc_link)
            await asyncio.Event().wait()

        task = asyncio.ensure_future(run(app, stop, link))
        await eventually(lambda: app.coordinator.snapshot.link_up, 5, "link up")
        await eventually(lambda: world.base.watchdog_armed, 5, "watchdog fed")
        assert linked  # the link runner was started with the station
        stop.set()
        await asyncio.wait_for(task, 5)
        assert world.base.command_log == []
        assert not app.coordinator.client.connected
