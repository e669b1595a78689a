"""The camera and IR sensor as parts of the simulated world: ports, subscription, control API."""

from __future__ import annotations

import asyncio
import math

import httpx

from asset_agent.precland.detect import PadDetector
from asset_agent.precland.transport import IrReceiver, stream_frames
from sim.camera.part import CameraPart
from sim.ir import IrPart
from sim.world import World, WorldConfig


async def test_camera_and_ir_parts_serve_in_the_world():
    pose = (0.3, -0.2, 2.5, 0.0, 0.0, 0.5)
    world = World(WorldConfig.for_tests(speed=2.0))
    world.add_part(CameraPart(lambda: pose))
    world.add_part(IrPart(lambda: pose))
    async with world:
        assert {"camera", "ir", "control"} <= set(world.ports)
        # frames from the world's camera port
        async for frame in stream_frames("127.0.0.1", world.ports["camera"]):
            det = PadDetector().detect(frame.image)
            break
        assert det.pattern is not None and abs(det.pattern.z - 2.5) < 0.02
        # IR: subscribe by talking to the sensor's port, then readings arrive
        receiver = IrReceiver()
        await receiver.start()
        try:
            receiver.subscribe("127.0.0.1", world.ports["ir"])
            reading = await asyncio.wait_for(receiver.queue.get(), 10.0)
        finally:
            receiver.close()
        assert (
            reading.detected
            and abs(reading.angle_y - math.atan2(0.3 * math.cos(0.5) - 0.2 * math.sin(0.5), 2.5))
            < 0.02
        )
        # control: image effects at run time
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as http:
            r = await http.put("/camera/effects", json={"exposure": 0.5, "noise_sigma": 3})
            assert r.status_code == 200
            status = (await http.get("/camera")).json()
            assert status["effects"]["exposure"] == 0.5 and status["port"] == world.ports["camera"]
            bad = await http.put("/camera/effects", json={"exposure": -1})
            assert bad.status_code in (400, 422)  # refused, never applied
