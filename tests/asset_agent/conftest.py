"""Fixtures for the autopilot adapter tests: a simulated autopilot on free ports and an adapter on it."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot, AutopilotConfig
from sim.vehicle.server import VehicleServer, run_vehicle
from sim.vehicle.standalone import OpenPad
from tests.polling import eventually

SPEED = 20.0


def fast_config(url: str, **overrides: object) -> AutopilotConfig:
    """An adapter configuration with short but load-tolerant timeouts for tests."""
    base: dict[str, object] = {
        "url": url,
        "link_timeout_s": 1.5,
        "command_timeout_s": 1.0,
        "command_retries": 3,
        "mission_timeout_s": 0.75,
        "mission_retries": 3,
    }
    base.update(overrides)
    return AutopilotConfig(**base)  # type: ignore[arg-type]


@pytest.fixture
def pad() -> OpenPad:
    """The always-open stand-in base."""
    return OpenPad()


@pytest.fixture
async def vehicle(pad: OpenPad) -> AsyncIterator[VehicleServer]:
    """A simulated autopilot at SPEED x on free UDP/TCP ports."""
    async with run_vehicle(speed=SPEED, seed=7, base=pad) as server:
        yield server


@pytest.fixture
async def autopilot(vehicle: VehicleServer) -> AsyncIterator[Autopilot]:
    """An adapter connected to `vehicle` over UDP, link up and streams requested."""
    ap = Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}"))
    await ap.start()
    try:
        await ap.wait_link(10)
        await asyncio.wait_for(ap.streams_requested.wait(), 10)
        await eventually(
            lambda: ap.state.lat is not None and ap.state.fix_type >= 3, 10, "position"
        )
        yield ap
    finally:
        await ap.close()
