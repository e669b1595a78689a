"""The fleet page's video panels in Debian's Chromium against a real server and a real WHIP
publisher: a panel holds a viewer session only while its UAV publishes, and the server's
`video_state` on the operator socket is what wakes it (no panel asks again and again); a UAV
described without a camera has no panel."""

from __future__ import annotations

import asyncio
import re

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, test_settings
from tests.console.browser import open_page, shot, sign_in, video_panel, whep_offers
from tests.polling import eventually
from tests.video.peers import publisher
from tests.video.test_video_api import uav_with_camera

pytestmark = pytest.mark.slow  # a browser: not in the fast lane


async def test_a_fleet_panel_holds_no_session_for_an_idle_uav_and_opens_one_when_it_publishes(
    database_url, superuser_email, browser
):
    from playwright.async_api import expect

    server = LiveServer(test_settings(database_url)).start()
    pub = None
    try:
        with httpx.Client(base_url=server.url, timeout=30) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "fleet-video")
            asset_id, asset_token = await asyncio.to_thread(uav_with_camera, tenant, sync_api)
            blind = await asyncio.to_thread(
                tenant.create_asset, "uav", attributes={"camera": False}
            )
        async with httpx.AsyncClient(base_url=server.url, timeout=30) as api:
            name = (await api.get(f"/api/v1/assets/{asset_id}", headers=tenant.h())).json()["name"]

            async def viewers() -> int:
                r = await api.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("operator"))
                return int(r.json()["viewers"])

            page, traffic = await open_page(browser, server.url + "/")
            await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
            _, state, video = video_panel(page, name)

            # idle: the panel says so and holds nothing on the server
            await expect(state).to_have_text(re.compile("^no signal"))
            assert await viewers() == 0 and whep_offers(traffic, asset_id) == 0
            # a UAV described without a camera has a card but no panel, and nothing is asked
            no_camera, _, _ = video_panel(page, blind["name"])
            await expect(no_camera.get_by_role("heading")).to_have_text(f"UAV {blind['name']}")
            await expect(no_camera.locator("video, figure.video")).to_have_count(0)
            assert not [u for u in traffic.urls if f"/{blind['id']}/video" in u], traffic.urls
            await shot(page, "fleet-video-idle")

            # the UAV publishes: the server's video_state wakes the panel, which opens one session
            pub = publisher(server.url, asset_id, asset_token, 320, 240, 20)
            await pub.publish_once()
            await expect(state).to_have_text("live", timeout=30_000)

            async def frames() -> bool:
                return int(await video.get_attribute("data-frames") or 0) > 10

            await eventually(frames, within=30, what="frames in the panel")
            assert await viewers() == 1 and whep_offers(traffic, asset_id) == 1
            await shot(page, "fleet-video-live")

            # it stops: the panel ends its session once the description says offline
            await pub.stop()
            await expect(state).to_have_text(re.compile("^no signal"), timeout=30_000)

            async def released() -> bool:
                return await viewers() == 0

            await eventually(released, within=10, what="the panel's session ended")

            # and publishes again: woken again, a second session
            await pub.publish_once()
            await expect(state).to_have_text("live", timeout=30_000)
            assert whep_offers(traffic, asset_id) == 2
            assert traffic.errors == []
            await page.context.close()
    finally:
        if pub is not None:
            await pub.stop()
            await pub.track.aclose()  # type: ignore[attr-defined]
        await asyncio.to_thread(server.stop)
