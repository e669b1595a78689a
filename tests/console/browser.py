"""Driving the console in Debian's headless Chromium with Playwright: one browser per test
module, pages at 1280×800 that record every request (origin, bytes transferred) as they load."""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

CHROMIUM = "/usr/bin/chromium"  # from apt (.ci/install-system.sh); never a downloaded browser
VIEWPORT = {"width": 1280, "height": 800}
SHOTS = os.environ.get("AEROBASE_SCREENSHOTS")  # a folder: the tests save their page images there


def chromium() -> str:
    """Debian's Chromium; its absence fails the test (CI installs it), never skips it."""
    assert os.path.exists(CHROMIUM), f"{CHROMIUM} is missing: run .ci/install-system.sh"
    return CHROMIUM


ARGS = [
    "--no-sandbox",  # CI runs as root
    "--allow-loopback-in-peer-connection",  # the test server's video candidates are on loopback
    "--disable-features=WebRtcHideLocalIpsWithMdns",  # real candidates, not .local names
]  # (as tests/video/test_viewer_browser.py; the page's muted <video> autoplays by itself)


async def launch() -> AsyncIterator[Any]:
    """A headless Chromium that may watch the test server's video over loopback WebRTC."""
    from playwright.async_api import async_playwright

    async with async_playwright() as pw:
        browser = await pw.chromium.launch(executable_path=chromium(), headless=True, args=ARGS)
        try:
            yield browser
        finally:
            await browser.close()


@dataclass
class Traffic:
    """What a page asked for and how many bytes came over the wire (headers and compressed bodies)."""

    urls: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)  # uncaught exceptions of the page's scripts
    transferred: dict[str, int] = field(default_factory=dict)

    def off_origin(self, origin: str) -> list[str]:
        """Requests to another host; a blob: URL has its creator's origin (blob:http://host/uuid)."""
        host = urlsplit(origin).netloc
        return [u for u in self.urls if urlsplit(u.removeprefix("blob:")).netloc != host]

    def total(self) -> int:
        return sum(self.transferred.values())


async def open_page(browser: Any, url: str) -> tuple[Any, Traffic]:
    """A fresh context (its own storage) and page, its traffic recorded from the first request."""
    context = await browser.new_context(viewport=VIEWPORT, timezone_id="UTC", locale="en-GB")
    page = await context.new_page()
    traffic = Traffic()
    page.on("request", lambda r: traffic.urls.append(r.url))
    page.on("websocket", lambda ws: traffic.urls.append(ws.url))
    cdp = await context.new_cdp_session(page)
    await cdp.send("Network.enable")
    ids: dict[str, str] = {}
    cdp.on(
        "Network.requestWillBeSent", lambda e: ids.__setitem__(e["requestId"], e["request"]["url"])
    )
    cdp.on(
        "Network.loadingFinished",
        lambda e: traffic.transferred.__setitem__(
            ids.get(e["requestId"], e["requestId"]), int(e["encodedDataLength"])
        ),
    )
    page.on("pageerror", lambda err: traffic.errors.append(str(err)))
    await page.goto(url)
    return page, traffic


SIGN_IN_MS = 20_000


async def sign_in(page: Any, email: str, password: str) -> None:
    """Sign in through the form; when the account has a live session, end it as the page offers."""
    from playwright.async_api import expect

    await page.get_by_label("E-mail").fill(email)
    await page.get_by_label("Password").fill(password)
    await page.get_by_label("Password").press("Enter")  # the keyboard submits the form
    fleet = page.get_by_role("heading", name="Fleet", exact=True)
    take_over = page.get_by_role("button", name="Sign in and end the other session")
    # each a round trip to the server, through nginx and a replica's container in the stack
    # test: 5 s (playwright's default) was once too short there, the machine building images
    # (the fleet page was up when the snapshot of the failure was taken)
    await expect(fleet.or_(take_over)).to_be_visible(timeout=SIGN_IN_MS)
    if await take_over.is_visible():
        await expect(page.get_by_role("alert")).to_contain_text("one live session per account")
        await take_over.click()
    await expect(fleet).to_be_visible(timeout=SIGN_IN_MS)


async def shot(page: Any, name: str) -> None:
    """Save the page as docs' screenshot `name`.png when AEROBASE_SCREENSHOTS names a folder."""
    if SHOTS:
        os.makedirs(SHOTS, exist_ok=True)
        await page.screenshot(path=str(Path(SHOTS) / f"{name}.png"))


def video_panel(page: Any, name: str) -> tuple[Any, Any, Any]:
    """The fleet page's card of the UAV `name`, its video state and its video (locators)."""
    card = page.get_by_role("region", name=f"UAV {name}")
    state = card.get_by_role("status", name=f"Video state of {name}")
    return card, state, card.get_by_label(f"Live video of {name}")


def whep_offers(traffic: Traffic, asset_id: str) -> int:
    """How many viewer sessions the page has asked the server for the asset's video."""
    return sum(1 for u in traffic.urls if u.endswith(f"/{asset_id}/video/whep"))
