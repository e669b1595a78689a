"""The GNSS receiver plugged into the simulated world: its port, position and control routes."""

from __future__ import annotations

import asyncio

import httpx
import pytest
from pyrtcm import RTCMReader

from protocol.rtcm import Reframer
from sim.gnss import GnssPart
from sim.gnss.sky import geodetic_to_ecef
from sim.world import World, WorldConfig
from tests.polling import eventually


async def test_world_serves_the_receiver_at_the_pad_with_its_control_routes() -> None:
    world = World(WorldConfig.for_tests(speed=20.0, seed=3))
    part = GnssPart(antenna_height_m=2.0)
    world.add_part(part)
    async with world:
        reader, writer = await asyncio.open_connection("127.0.0.1", world.ports["gnss"])
        reframer, frames = Reframer(), []
        try:

            async def pump() -> None:
                while data := await reader.read(65536):
                    frames.extend(reframer.feed(data))

            task = asyncio.create_task(pump())
            await eventually(lambda: len(frames) >= 8)
            task.cancel()
        finally:
            writer.close()
        ref = RTCMReader.parse(frames[0], validate=1)
        lat, lon, h = world.base.pad_geodetic
        assert (ref.DF025, ref.DF026, ref.DF027) == pytest.approx(
            geodetic_to_ecef(lat, lon, h + 2.0), abs=1e-4
        )
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as http:
            status = (await http.get("/gnss")).json()
            assert status["config"]["seed"] == 3
            r = await http.post("/gnss/faults", json={"streaming": False})
            assert r.json()["streaming"] is False
        assert part.receiver is not None and part.receiver.faults.streaming is False
