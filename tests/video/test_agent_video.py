"""The agent publishes the simulated downward camera: `[video]` in agent.toml, WHIP to the server."""

from __future__ import annotations

import asyncio
import time

import httpx
import pytest

from asset_agent.config import AgentConfig
from asset_agent.video.publish import video_publisher
from sim.camera.server import CameraServer
from tests.conftest import LiveServer, Tenant
from tests.polling import eventually
from tests.video.peers import Viewer
from tests.video.test_video_api import uav_with_camera


class WallClock:
    """The world's clock at real time (the camera's capture pacing)."""

    def now(self) -> float:
        return time.monotonic()

    async def sleep(self, sim_seconds: float) -> None:
        await asyncio.sleep(sim_seconds)


def test_video_is_off_unless_enabled_and_needs_a_source():
    off = AgentConfig.model_validate({"precland": {"camera_port": 5000}})
    assert video_publisher(off, "http://x", "a", lambda: None) is None
    no_source = AgentConfig.model_validate({"video": {"enabled": True}})
    assert video_publisher(no_source, "http://x", "a", lambda: None) is None


@pytest.mark.slow
async def test_the_agent_streams_the_simulated_camera_at_the_configured_size(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    camera = CameraServer(lambda: (0.0, 0.0, 6.0, 0.0, 0.0, 0.0), WallClock(), fps=15)
    port = await camera.start()
    asset_id, token = uav_with_camera(
        video_tenant, video_api, {"width": 480, "height": 360, "fps": 15}
    )
    config = AgentConfig.model_validate(
        {"video": {"enabled": True, "camera_port": port, "width": 480, "height": 360, "fps": 15}}
    )
    publisher = video_publisher(config, video_server.url, asset_id, lambda: token)
    assert publisher is not None
    running = asyncio.create_task(publisher.run())
    viewer = Viewer(video_server.url, asset_id, video_tenant.tokens["viewer"])
    try:
        assert (await viewer.offer()).status_code == 201
        await eventually(lambda: viewer.frames >= 30, within=40, what="30 camera frames")
        assert viewer.sizes == {(480, 360)}  # the 640x480 render, scaled to the configured size
        assert camera.frames_sent >= 30
    finally:
        running.cancel()
        await viewer.close()
        await publisher.stop()
        await publisher.track.aclose()
        await camera.stop()
