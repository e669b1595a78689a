"""A real browser watches: Playwright drives Debian's headless Chromium on the viewer page."""

from __future__ import annotations

import httpx
import pytest
from playwright.async_api import async_playwright

from tests.conftest import LiveServer, Tenant
from tests.video.peers import publisher
from tests.video.test_video_api import uav_with_camera

CHROMIUM = "/usr/bin/chromium"  # Debian's (.ci/install-system.sh); never `playwright install`
CHROMIUM_ARGS = [
    "--no-sandbox",  # the tests run as root
    "--allow-loopback-in-peer-connection",  # the test server's candidates are on loopback
    "--disable-features=WebRtcHideLocalIpsWithMdns",  # real candidates, not .local names
    "--autoplay-policy=no-user-gesture-required",
]


@pytest.mark.slow
async def test_headless_chromium_decodes_more_than_60_frames_on_the_viewer_page(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    camera = {"width": 640, "height": 480, "fps": 30}
    asset_id, asset_token = uav_with_camera(video_tenant, video_api, camera)
    pub = publisher(video_server.url, asset_id, asset_token, 640, 480, 30)
    await pub.publish_once()
    try:
        async with async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = await browser.new_page()
                token = video_tenant.tokens["viewer"]
                await page.goto(f"{video_server.url}/video/viewer#asset={asset_id}&token={token}")
                await page.wait_for_function(
                    "window.aerobaseViewer && window.aerobaseViewer.frames > 60", timeout=60_000
                )
                state = await page.evaluate("window.aerobaseViewer")
                assert state["state"] == "live" and state["error"] is None, state
                assert (state["width"], state["height"]) == (640, 480), state
                assert await page.text_content("#state") == "live"
            finally:
                await browser.close()
    finally:
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


@pytest.mark.slow
async def test_the_page_shows_reconnecting_across_an_agent_link_cut_then_frames_again(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    import asyncio

    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    running = asyncio.create_task(pub.run())
    try:
        async with async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = await browser.new_page()
                token = video_tenant.tokens["viewer"]
                await page.goto(f"{video_server.url}/video/viewer#asset={asset_id}&token={token}")
                await page.wait_for_function("window.aerobaseViewer.frames > 20", timeout=60_000)
                # the link is cut: the agent's peer dies and it does not come back yet
                running.cancel()
                await pub._close_pc()
                await page.wait_for_function(
                    "window.aerobaseViewer.state === 'reconnecting'", timeout=20_000
                )
                before = await page.evaluate("window.aerobaseViewer.frames")
                # the link is back: the agent publishes again; the page was never reloaded
                running = asyncio.create_task(pub.run())
                await page.wait_for_function(
                    f"window.aerobaseViewer.frames > {before + 20} && "
                    "window.aerobaseViewer.state === 'live'",
                    timeout=60_000,
                )
            finally:
                await browser.close()
    finally:
        running.cancel()
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]
