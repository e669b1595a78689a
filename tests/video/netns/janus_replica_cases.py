"""Two replicas on one Janus, run by test_video_janus.py in its private network: a replica that
never made an asset's mountpoint (restarted, or given the asset by the proxy's hash) adopts it
from Janus as it is, so the stream's state, new viewers and the UAV's RTP port stay as they were,
and a viewer of the first replica is not cut off.

Not collected on its own (not named test_*): outside that namespace Janus has no interface to use.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, auth, test_settings
from tests.polling import eventually
from tests.video.netns.janus_cases import JanusViewer, janus, rtp_publisher, server, tenant  # noqa: F401
from tests.video.netns.janus_env import Janus
from tests.video.test_video_api import uav_with_camera

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def second(database_url: str, janus: Janus) -> Iterator[LiveServer]:  # noqa: F811
    """Another replica on the same database and Janus."""
    s = LiveServer(
        test_settings(database_url, janus_url=janus.url, janus_rtp_host="127.0.0.1")
    ).start()
    yield s
    s.stop()


async def test_a_replica_that_never_made_the_mountpoint_adopts_it_and_cuts_no_one_off(
    server: LiveServer,  # noqa: F811
    second: LiveServer,
    tenant: Tenant,  # noqa: F811
):
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    pub = rtp_publisher(server, asset_id, token)  # asks the first replica where to send
    sending = asyncio.create_task(pub.run())
    first_viewer = JanusViewer(server.url, asset_id, tenant.tokens["viewer"])
    second_viewer = JanusViewer(second.url, asset_id, tenant.tokens["operator"])
    try:
        await eventually(lambda: pub.packets > 50, within=20, what="RTP sent to Janus")
        assert (await first_viewer.start()).status_code == 201
        await eventually(lambda: first_viewer.frames >= 20, within=30, what="frames on the first")
        assert pub.target is not None
        port = pub.target[1]

        async with httpx.AsyncClient(base_url=second.url, timeout=30) as other:
            video = f"/api/v1/assets/{asset_id}/video"
            desc = (await other.get(video, headers=tenant.h("viewer"))).json()
            assert desc["state"] == "live" and desc["viewers"] == 1, desc
            r = await second_viewer.start()
            assert r.status_code == 201, r.text
            await eventually(
                lambda: second_viewer.frames >= 20, within=30, what="frames on the second"
            )
            # the UAV asking this replica gets the same port: nothing destroyed and made again
            again = await other.post(f"{video}/rtp", headers=auth(token))
            assert again.status_code == 200 and again.json()["port"] == port, again.text

        before = first_viewer.frames
        await eventually(
            lambda: first_viewer.frames > before + 30,
            within=30,
            what="the first replica's viewer still getting frames",
        )
    finally:
        await first_viewer.close()
        await second_viewer.close()
        sending.cancel()
        await pub.track.aclose()
