"""The minimal viewer page (one HTML file and one ES module), served beside the API."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from fastapi import APIRouter, Response

router = APIRouter(include_in_schema=False)
STATIC = Path(__file__).parent / "static"


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


@router.get("/video/viewer.js")
async def viewer_module() -> Response:
    """The viewer's ES module."""
    return Response(
        _read("viewer.js"),
        media_type="text/javascript; charset=utf-8",
        headers={"Cache-Control": "no-cache"},
    )
