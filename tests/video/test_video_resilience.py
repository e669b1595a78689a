"""The stream survives the drone's link: viewers keep their sessions across a re-publish."""

from __future__ import annotations

import asyncio

import httpx
import pytest

from tests.conftest import LiveServer, Tenant
from tests.polling import eventually
from tests.video.peers import Viewer, publisher
from tests.video.test_video_api import uav_with_camera


@pytest.mark.slow
async def test_viewers_get_frames_again_after_the_agent_link_is_cut_and_it_republishes(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    running = asyncio.create_task(pub.run())
    viewer = Viewer(video_server.url, asset_id, video_tenant.tokens["viewer"])
    try:
        assert (await viewer.offer()).status_code == 201
        await eventually(lambda: viewer.frames >= 20, within=30, what="frames before the cut")
        # the cut: the agent's peer dies without a goodbye (no WHIP DELETE), as on a lost link
        assert pub._pc is not None
        await pub._pc.close()
        await eventually(lambda: pub.publications >= 2, within=20, what="the agent re-publishing")
        before = viewer.frames
        await eventually(
            lambda: viewer.frames >= before + 20, within=30, what="frames after the re-publish"
        )
        assert viewer.sizes == {(320, 240)}
        async with httpx.AsyncClient(base_url=video_server.url) as c:
            r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h("viewer"))
        assert r.json()["state"] == "live" and r.json()["viewers"] == 1
    finally:
        running.cancel()
        await viewer.close()
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


@pytest.mark.slow
async def test_a_viewer_that_vanishes_is_reaped_and_frees_its_place(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    await pub.publish_once()
    viewer = Viewer(video_server.url, asset_id, video_tenant.tokens["viewer"])
    try:
        assert (await viewer.offer()).status_code == 201
        await eventually(lambda: viewer.frames >= 5, within=30, what="frames")

        async def viewers() -> int:
            async with httpx.AsyncClient(base_url=video_server.url) as c:
                r = await c.get(
                    f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h("viewer")
                )
            return int(r.json()["viewers"])

        assert await viewers() == 1
        await viewer.close(delete=False)  # gone without a DELETE: a closed tab, a lost network

        # aiortc's peer sees the DTLS close at once; without it ICE consent lapses within ~30 s
        async def reaped() -> bool:
            return await viewers() == 0

        await eventually(reaped, within=40, what="the viewer reaped")
    finally:
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]
