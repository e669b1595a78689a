"""The console's fleet page on the Janus path, in Debian's Chromium, run by test_video_janus.py in
its private network: the panel of an idle UAV holds no session; the server's `video_state`, sent
once the UAV's RTP reaches Janus, wakes it; it answers Janus's offer and shows the frames; when
the RTP stops (Janus says nothing then) the panel finds the UAV offline and lets its session go.

Not collected on its own (not named test_*): outside that namespace Janus has no interface to use.
"""

from __future__ import annotations

import asyncio
import re

import httpx
import pytest

from tests.conftest import LiveServer, Tenant
from tests.console.browser import open_page, sign_in, video_panel, whep_offers
from tests.polling import eventually
from tests.video.netns.janus_cases import janus, rtp_publisher, server, tenant  # noqa: F401
from tests.video.test_video_api import uav_with_camera
from tests.video.test_viewer_browser import CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.slow


async def test_a_fleet_panel_wakes_when_the_uavs_rtp_reaches_janus_and_sleeps_when_it_stops(
    server: LiveServer,  # noqa: F811
    tenant: Tenant,  # noqa: F811
):
    from playwright.async_api import async_playwright, expect

    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    async with httpx.AsyncClient(base_url=server.url, timeout=30) as api:
        name = (await api.get(f"/api/v1/assets/{asset_id}", headers=tenant.h())).json()["name"]

        async def viewers() -> int:
            r = await api.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("operator"))
            return int(r.json()["viewers"])

        async with async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            pub = rtp_publisher(server, asset_id, token)
            sending: asyncio.Task[None] | None = None
            try:
                page, traffic = await open_page(browser, server.url + "/")
                await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
                card, state, video = video_panel(page, name)

                await expect(state).to_have_text(re.compile("^no signal"))
                assert whep_offers(traffic, asset_id) == 0 and await viewers() == 0

                sending = asyncio.create_task(pub.run())
                await expect(state).to_have_text("live", timeout=40_000)

                async def frames() -> bool:
                    return int(await video.get_attribute("data-frames") or 0) > 10

                await eventually(frames, within=30, what="Janus's frames in the panel")
                assert whep_offers(traffic, asset_id) == 1 and await viewers() == 1
                assert "janus" in (await card.text_content() or "")

                sending.cancel()  # the RTP stops; Janus announces nothing
                await expect(state).to_have_text(re.compile("^no signal"), timeout=40_000)

                async def released() -> bool:
                    return await viewers() == 0

                await eventually(released, within=20, what="the panel's Janus session ended")
                assert whep_offers(traffic, asset_id) == 1 and traffic.errors == []
            finally:
                if sending is not None:
                    sending.cancel()
                await pub.track.aclose()
                await browser.close()
