"""A fleet page of many UAVs in Debian's Chromium: the browser skips rendering the cards off the
screen (content-visibility), and the page skips drawing their maps; a card scrolled into view shows
its UAV where it is now, drawn late but not stale. Real server, a real asset link sending."""

from __future__ import annotations

import asyncio
import base64
import re

import httpx
import pytest

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from protocol.telemetry_payloads import Battery, Position, UavTelemetry
from tests.conftest import LiveServer, Tenant, test_settings
from tests.console.browser import open_page, sign_in, whep_offers
from tests.polling import eventually
from tests.video.peers import publisher
from tests.video.test_video_api import uav_with_camera

pytestmark = pytest.mark.slow  # a browser: not in the fast lane

BASE = (41.0, -8.6)
UAVS = 6  # the last card is far below a 1280×800 screen
M_PER_DEG_LAT = 111_320.0  # the console's metres() is equirectangular; 20 m north reads as 20


async def test_an_off_screen_card_draws_its_uavs_map_as_it_comes_into_view(
    database_url, superuser_email, browser, tmp_path
):
    from playwright.async_api import expect

    server = LiveServer(test_settings(database_url)).start()
    try:
        with httpx.Client(base_url=server.url, timeout=30) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "fleet-many")
            attributes = {"latitude": BASE[0], "longitude": BASE[1]}
            await asyncio.to_thread(tenant.create_asset, "landing_base", attributes=attributes)
            uavs = [await asyncio.to_thread(tenant.create_asset, "uav") for _ in range(UAVS)]
        page, traffic = await open_page(browser, server.url + "/")
        await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
        cards = page.get_by_role("region", name=re.compile("^UAV "))
        await expect(cards).to_have_count(UAVS)
        # (textContent: the innerText of a card whose rendering is skipped is empty)
        shown_last = await cards.last.get_by_role("heading").text_content()
        last = next(u for u in uavs if f"UAV {u['name']}" == shown_last)
        card = page.get_by_role("region", name=f"UAV {last['name']}")
        track = card.get_by_role("img", name=re.compile(f"^Live track of {last['name']}"))
        await expect(track).to_have_attribute("aria-label", re.compile("0 track points"))
        # off the screen, the browser skips the card's rendering (what the page's deferral keys on)
        skipped = "el => !el.checkVisibility({contentVisibilityAuto: true})"
        assert await card.locator("dl").evaluate(skipped)

        cfg = decrypt_config(base64.b64decode(last["config_file"]), "asset-password-123")
        link = Link(server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=1)
        await link.start()
        try:
            await link.wait_connected(15)
            lat = BASE[0] + 20 / M_PER_DEG_LAT
            sample = UavTelemetry(
                position=Position(lat=lat, lon=BASE[1], alt_msl_m=150.0, alt_rel_m=20.0),
                battery=Battery(percent=80.0, voltage_v=16.0, current_a=10.0),
                armed=True,
            )
            await link.send_telemetry(sample)
            assert await link.flush(15)
            # its values follow off the screen (the text is the page's, rendered or not)
            await expect(card).to_contain_text("20.0 m above home")
            assert await card.locator("dl").evaluate(skipped)
            # ...its map waits (drawn in the same update as the values, so no race here)
            assert "0 track points" in str(await track.get_attribute("aria-label"))
            await card.scroll_into_view_if_needed()
            await expect(track).to_have_attribute(
                "aria-label", re.compile(r"1 track points.*; UAV 20\.0 m north, 0 m east")
            )
        finally:
            await link.stop()
        assert traffic.errors == []
        await page.context.close()
    finally:
        await asyncio.to_thread(server.stop)


async def test_only_the_cards_on_the_screen_hold_a_video_session(
    database_url, superuser_email, browser
):
    from playwright.async_api import expect

    server = LiveServer(test_settings(database_url)).start()
    publishers = []
    try:
        with httpx.Client(base_url=server.url, timeout=30) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "fleet-many-video")
            uavs = [await asyncio.to_thread(uav_with_camera, tenant, sync_api) for _ in range(UAVS)]
        async with httpx.AsyncClient(base_url=server.url, timeout=30) as api:

            async def viewers(asset_id: str) -> int:
                r = await api.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("operator"))
                return int(r.json()["viewers"])

            names = {}
            for asset_id, _ in uavs:
                r = await api.get(f"/api/v1/assets/{asset_id}", headers=tenant.h())
                names[r.json()["name"]] = asset_id
            for asset_id, token in uavs:  # every UAV streams
                pub = publisher(server.url, asset_id, token, 320, 240, 15)
                publishers.append(pub)
                await pub.publish_once()
            page, traffic = await open_page(browser, server.url + "/")
            await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
            cards = page.get_by_role("region", name=re.compile("^UAV "))
            await expect(cards).to_have_count(UAVS)
            heads = [await c.get_by_role("heading").text_content() for c in await cards.all()]
            first, last = (names[str(h).removeprefix("UAV ")] for h in (heads[0], heads[-1]))
            state_of = {
                i: page.get_by_role("status", name=f"Video state of {n}") for n, i in names.items()
            }
            await expect(state_of[first]).to_have_text("live", timeout=30_000)
            await expect(state_of[last]).to_have_text("paused (off screen)")
            assert await viewers(first) == 1 and await viewers(last) == 0

            assert whep_offers(traffic, last) == 0
            # scrolled to the last card: it watches, and the first, now off the screen, lets go
            await cards.last.scroll_into_view_if_needed()
            await expect(state_of[last]).to_have_text("live", timeout=30_000)
            await expect(state_of[first]).to_have_text("paused (off screen)")

            async def moved() -> bool:
                return await viewers(last) == 1 and await viewers(first) == 0

            await eventually(moved, within=10, what="the session moved to the card on the screen")
            assert traffic.errors == []
            await page.context.close()
    finally:
        for pub in publishers:
            await pub.stop()
            await pub.track.aclose()  # type: ignore[attr-defined]
        await asyncio.to_thread(server.stop)
