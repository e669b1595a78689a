"""The console is served at `/` from the package: its page, its modules, caching and compression,
without touching the API's own routes and 404s."""

from __future__ import annotations

import gzip
import re

import httpx

from server.console.endpoints import STATIC, load


def _assets(page: str) -> list[str]:
    return re.findall(r'(?:href|src)="(/console/[^"]+)"', page)


def test_the_page_is_served_revalidated_with_a_strict_policy(api: httpx.Client):
    r = api.get("/")
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/html")
    assert r.headers["cache-control"] == "no-cache" and r.headers["etag"]
    policy = r.headers["content-security-policy"]
    assert "default-src 'self'" in policy and "connect-src 'self'" in policy
    assert "{{ASSETS}}" not in r.text
    again = api.get("/", headers={"If-None-Match": r.headers["etag"]})
    assert again.status_code == 304 and not again.content


def test_modules_are_immutable_under_the_digest_and_compressed(api: httpx.Client):
    page = api.get("/").text
    assets = _assets(page)
    digest, files = load()
    assert assets and all(a.startswith(f"/console/{digest}/") for a in assets)
    r = api.get(f"/console/{digest}/js/app.js", headers={"Accept-Encoding": "gzip"})
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/javascript")
    assert r.headers["cache-control"] == "public, max-age=31536000, immutable"
    assert r.headers["content-encoding"] == "gzip"
    assert r.content == (STATIC / "js" / "app.js").read_bytes()  # httpx decoded the gzip
    # an older page asking for an older release is answered, but not cached for long
    old = api.get("/console/000000000000/js/app.js")
    assert old.status_code == 200 and old.headers["cache-control"] == "no-cache"
    # the whole console compresses under the page-weight target (300 kB first load)
    compressed = sum(len(gzip.compress(a.body)) for a in files.values())
    assert compressed < 300_000, compressed


def test_unknown_files_and_api_paths_keep_their_json_404(api: httpx.Client):
    digest, _ = load()
    for path in (f"/console/{digest}/js/nope.js", f"/console/{digest}/index.html", "/api/v1/nope"):
        r = api.get(path)
        assert r.status_code == 404, path
        assert r.json()["error"]["code"] == "not_found", path
    assert (
        api.get("/api/v1/missions/")
        .json()["error"]["message"]
        .endswith("API paths have no trailing slash (/api/v1/missions)")
    )
    # the console is a client of the API, not part of its document
    paths = api.get("/api/openapi.json").json()["paths"]
    assert "/" not in paths and not any(p.startswith("/console") for p in paths)
    assert api.get("/api/docs").status_code == 200


async def test_a_tile_server_is_named_to_the_page_and_allowed_by_its_policy_only_when_set():
    import pytest
    from fastapi import FastAPI
    from pydantic import ValidationError

    from server.config import Settings
    from server.console.endpoints import console_router

    async def page(tile_url: str | None) -> httpx.Response:
        app = FastAPI()
        app.include_router(console_router(tile_url=tile_url))
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://console") as client:
            return await client.get("/")

    plain = await page(None)
    assert "aerobase-map-tiles" not in plain.text
    assert "img-src 'self' data: blob:;" in plain.headers["content-security-policy"]
    tiled = await page("https://tiles.example.org/osm/{z}/{x}/{y}.png")
    assert (
        '<meta name="aerobase-map-tiles" content="https://tiles.example.org/osm/{z}/{x}/{y}.png">'
        in tiled.text
    )
    policy = tiled.headers["content-security-policy"]
    assert "img-src 'self' data: blob: https://tiles.example.org;" in policy
    assert "connect-src 'self';" in policy  # tiles are images, nothing else may go there
    assert tiled.headers["etag"] != plain.headers["etag"]
    for bad in (
        "ftp://t/{z}/{x}/{y}",
        "//t/{z}/{x}/{y}",
        "https://t/{z}/{x}",
        'https://t/"{z}{x}{y}',
    ):
        with pytest.raises(ValidationError):
            Settings(map_tile_url=bad)
    assert Settings(map_tile_url="").map_tile_url is None
    assert Settings(map_tile_url="/tiles/{z}/{x}/{y}.png").map_tile_url == "/tiles/{z}/{x}/{y}.png"
