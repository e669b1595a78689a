"""Issue 48 finding 11: `/api/docs` renders in headless Chromium with no network but the server's
(Swagger UI's files come from a Python package, not a CDN), and `/openapi.json` leads to the
document."""

from __future__ import annotations

from typing import Any
from urllib.parse import urlsplit

import httpx
from playwright.async_api import expect

from tests.conftest import LiveServer


async def test_the_api_docs_render_with_no_network_beyond_the_server(
    browser: Any, live_server: LiveServer
):
    server = urlsplit(live_server.url).netloc
    refused: list[str] = []

    async def only_the_server(route: Any) -> None:
        if urlsplit(route.request.url).netloc == server:
            await route.continue_()
        else:  # as a machine without internet would: the request fails
            refused.append(route.request.url)
            await route.abort("internetdisconnected")

    context = await browser.new_context()
    await context.route("**/*", only_the_server)
    page = await context.new_page()
    asked: list[str] = []
    errors: list[str] = []
    page.on("request", lambda r: asked.append(r.url))
    page.on("pageerror", lambda err: errors.append(str(err)))
    try:
        await page.goto(f"{live_server.url}/api/docs")
        await expect(page.locator(".swagger-ui .info .title")).to_contain_text(
            "Aerobase", timeout=20_000
        )
        # the operations are listed, read from /api/openapi.json
        health = page.locator(".opblock-summary-path", has_text="/api/health").first
        await expect(health).to_be_visible()
        assert refused == [], refused
        assert {urlsplit(u).netloc for u in asked if not u.startswith("data:")} == {server}
        assert errors == []
    finally:
        await context.close()


def test_openapi_json_at_the_root_leads_to_the_document(api: httpx.Client):
    r = api.get("/openapi.json")
    assert r.status_code == 308 and r.headers["location"] == "/api/openapi.json"
    r = api.get("/openapi.json", follow_redirects=True)
    assert r.status_code == 200 and r.json()["info"]["title"] == "Aerobase"
    page = api.get("/api/docs").text
    assert "cdn." not in page and "https://" not in page, page
    for path in ("swagger-ui-bundle.js", "swagger-ui.css"):
        assert api.get(f"/api/docs/files/{path}").status_code == 200
    assert api.get("/api/docs/files/index.html").status_code == 404
