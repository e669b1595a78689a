"""Serving the console: `/` is its page, `/console/<digest>/<file>` its modules and styles.

The files are read once when the app is built. Their combined digest is part of every asset's
URL, so assets are cached for a year (`immutable`) and a new release is a new URL; the page itself
is revalidated on every load (`no-cache` with an ETag). Compression is the app's gzip middleware.
No route here is in the OpenAPI document: the console is a client of the API, not part of it.
"""

from __future__ import annotations

import hashlib
import html
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from fastapi import APIRouter, Request, Response
from starlette.exceptions import HTTPException as StarletteHTTPException

STATIC = Path(__file__).parent / "static"
TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
    ".txt": "text/plain; charset=utf-8",
}
# everything the page loads comes from its own origin; sockets to the same host. The live video is
# a MediaStream (WebRTC is outside the policy); a recorded segment plays from a blob: URL (its
# download needs the bearer token, which a <video src> cannot send).
POLICY = (
    "default-src 'self'; connect-src 'self'; img-src 'self' data: blob:; media-src 'self' blob:; "
    "style-src 'self'; script-src 'self'; object-src 'none'; base-uri 'none'; "
    "frame-ancestors 'none'"
)
YEAR = "public, max-age=31536000, immutable"


@dataclass(frozen=True)
class Asset:
    """One file of the console, in memory, with its validator."""

    body: bytes
    media_type: str
    etag: str


def load(root: Path = STATIC) -> tuple[str, dict[str, Asset]]:
    """Every servable file under `root` keyed by its relative path, and the digest of them all."""
    files: dict[str, Asset] = {}
    whole = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        media = TYPES.get(path.suffix)
        if media is None:
            continue
        body = path.read_bytes()
        name = path.relative_to(root).as_posix()
        whole.update(name.encode() + b"\0" + body + b"\0")
        files[name] = Asset(body, media, '"' + hashlib.sha256(body).hexdigest()[:20] + '"')
    return whole.hexdigest()[:12], files


def _answer(request: Request, asset: Asset, cache: str, extra: dict[str, str]) -> Response:
    headers = {"Cache-Control": cache, "ETag": asset.etag, **extra}
    if asset.etag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers=headers)
    return Response(asset.body, media_type=asset.media_type, headers=headers)


def _page_config(tile_url: str | None) -> tuple[bytes, str]:
    """The page's settings (a <meta> the modules read) and the image sources its policy allows."""
    if not tile_url:
        return b"", "'self' data: blob:"
    meta = f'<meta name="aerobase-map-tiles" content="{html.escape(tile_url)}">'.encode()
    parts = urlsplit(tile_url)
    origin = f"{parts.scheme}://{parts.netloc}" if parts.netloc else ""
    return meta, " ".join(x for x in ("'self' data: blob:", origin) if x)


def console_router(root: Path = STATIC, tile_url: str | None = None) -> APIRouter:
    """The console's two routes over the files under `root`; `tile_url`: the map's tiles."""
    digest, files = load(root)
    base = f"/console/{digest}"
    index = files["index.html"]
    meta, images = _page_config(tile_url)
    body = index.body.replace(b"{{ASSETS}}", base.encode()).replace(b"{{CONFIG}}", meta)
    page = Asset(body, index.media_type, '"' + hashlib.sha256(body).hexdigest()[:20] + '"')
    router = APIRouter(include_in_schema=False)
    security = {
        "Content-Security-Policy": POLICY.replace(
            "img-src 'self' data: blob:", f"img-src {images}"
        ),
        "X-Content-Type-Options": "nosniff",
        "Referrer-Policy": "no-referrer",
    }

    @router.get("/")
    async def console_page(request: Request) -> Response:
        """The console's single page (revalidated on every load)."""
        return _answer(request, page, "no-cache", security)

    @router.get("/console/{version}/{path:path}")
    async def console_file(version: str, path: str, request: Request) -> Response:
        """A module, style sheet or image of the console; immutable under the current digest."""
        asset = files.get(path)
        if asset is None or path == "index.html":
            raise StarletteHTTPException(404, f"no console file {path}")
        # an old page asking for an older release gets today's file, revalidated, not cached
        cache = YEAR if version == digest else "no-cache"
        return _answer(request, asset, cache, {"X-Content-Type-Options": "nosniff"})

    return router
