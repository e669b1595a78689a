"""The minimal viewer page and the WHEP client module it shares with the console (`/video/whep.js`)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from fastapi import APIRouter, Response
from starlette.exceptions import HTTPException as StarletteHTTPException

router = APIRouter(include_in_schema=False)
STATIC = Path(__file__).parent / "static"
MODULES = {"viewer", "whep"}  # the ES modules under static/; whep.js is imported by the console


@cache
def _read(name: str) -> bytes:
    return (STATIC / name).read_bytes()


@router.get("/video/viewer")
async def viewer_page() -> Response:
    """The WHEP viewer page (the asset and token come in the URL's fragment)."""
    return Response(
        _read("viewer.html"),
        media_type="text/html; charset=utf-8",
        headers={"Cache-Control": "no-cache", "Referrer-Policy": "no-referrer"},
    )


@router.get("/video/{name}.js")
async def viewer_module(name: str) -> Response:
    """The viewer page's module, or the WHEP client it shares with the console (`whep.js`)."""
    if name not in MODULES:
        raise StarletteHTTPException(404, f"no video module {name}.js")
    return Response(
        _read(f"{name}.js"),
        media_type="text/javascript; charset=utf-8",
        headers={"Cache-Control": "no-cache", "X-Content-Type-Options": "nosniff"},
    )
