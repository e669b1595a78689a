"""Helpers for the daemon tests: a simulated world, the daemon against it, a waiter."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest

from base_station.config import StationConfig
from base_station.main import App, setup
from base_station.station import Result, Station
from sim.world import World, WorldConfig
from tests.polling import eventually

SPEED = 15.0  # panels travel in 0.8 s wall, lift in 0.53 s


def station_config(plc_port: int, speed: float = SPEED, **uav: Any) -> StationConfig:
    """A daemon configuration for a world running at `speed`."""
    return StationConfig.model_validate(
        {
            "plc": {
                "host": "127.0.0.1",
                "port": plc_port,
                "poll_hz": 20.0,
                "timeout_s": 1.0,
                "reconnect_s": 0.1,
            },
            "motion": {
                "panels_travel_s": 12.0 / speed,
                "lift_travel_s": 8.0 / speed,
                "timeout_margin_s": 1.0,
            },
            "uav": {
                "min_mass_g": 1200,
                "max_mass_g": 1800,
                "scale_tare_g": 15.0,
                "stable_s": 0.5,
                "stable_tolerance_g": 40.0,
                **uav,
            },
            "weather": {
                "max_wind_mps": 8.0,
                "max_gust_mps": 12.0,
                "max_rain_mm_h": 0.0,
                "min_temperature_c": -5.0,
                "max_temperature_c": 40.0,
            },
        }
    )


@dataclass
class Rig:
    """A running world and a running daemon against it."""

    world: World
    app: App
    control: httpx.AsyncClient

    @property
    def station(self) -> Station:
        """The daemon's command/event facade."""
        return self.app.station

    async def inject(self, path: str, body: dict[str, Any]) -> dict[str, Any]:
        """POST to the simulator's control interface."""
        r = await self.control.post(path, json=body)
        assert r.status_code == 200, r.text
        return r.json()

    async def link_up(self, up: bool = True, within: float = 5.0) -> None:
        """Wait until the daemon's view of the PLC link is `up`."""
        await eventually(lambda: self.app.coordinator.snapshot.link_up is up, within, f"link {up}")

    def commands(self) -> list[str]:
        """Command coils the PLC has processed so far (ground truth)."""
        return [c.coil for c in self.world.base.command_log]


async def start_daemon(config: StationConfig) -> App:
    """Build and start a daemon (coordinator polling)."""
    app = setup(config)
    await app.coordinator.start()
    return app


async def stop_daemon(app: App) -> None:
    """Stop a daemon started by `start_daemon`."""
    await app.station.shutdown()
    await app.coordinator.stop()


@contextlib.asynccontextmanager
async def rig_at(speed: float = SPEED, seed: int = 11, **uav: Any) -> AsyncIterator[Rig]:
    """A world at `speed` with calm forced weather, and a daemon connected to it."""
    async with World(WorldConfig.for_tests(speed=speed, seed=seed)) as world:
        world.weather.force(wind_mps=2.0, gust_mps=3.0, rain_mm_h=0.0, temperature_c=15.0)
        app = await start_daemon(station_config(world.ports["plc"], speed, **uav))
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as c:
            r = Rig(world, app, c)
            try:
                await r.link_up()
                await eventually(lambda: world.base.watchdog_armed, 5.0, "watchdog armed")
                yield r
            finally:
                await stop_daemon(r.app)


@pytest.fixture
async def rig() -> AsyncIterator[Rig]:
    """World at SPEED and a daemon connected to it."""
    async with rig_at(SPEED) as r:
        yield r


async def run(station: Station, name: str, params: dict[str, Any] | None = None) -> Result:
    """Run a command to its result."""
    return await station.run(name, params)
