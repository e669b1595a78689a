"""The API's documentation page, served from files a Python package ships (swagger-ui-bundle-v2),
so that `/api/docs` renders with no internet and no other origin; `/openapi.json`, where tools
look first, leads to the document at `/api/openapi.json`."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from swagger_ui_bundle import swagger_ui_path

OPENAPI_URL = "/api/openapi.json"
DOCS_URL = "/api/docs"
FILES = Path(swagger_ui_path)
# the page needs these three; nothing else of the package is served
SERVED = {"swagger-ui-bundle.js", "swagger-ui.css", "favicon-32x32.png"}


def docs_router(title: str) -> APIRouter:
    """`/api/docs`, its files under `/api/docs/files/`, and `/openapi.json`."""
    router = APIRouter(include_in_schema=False)

    @router.get(DOCS_URL)
    async def docs() -> HTMLResponse:
        """Swagger UI over the OpenAPI document, every file from this server."""
        return get_swagger_ui_html(
            openapi_url=OPENAPI_URL,
            title=f"{title} — API",
            swagger_js_url=f"{DOCS_URL}/files/swagger-ui-bundle.js",
            swagger_css_url=f"{DOCS_URL}/files/swagger-ui.css",
            swagger_favicon_url=f"{DOCS_URL}/files/favicon-32x32.png",
        )

    @router.get(DOCS_URL + "/files/{name}")
    async def docs_file(name: str) -> FileResponse:
        """One of the page's files, from the package."""
        if name not in SERVED:
            raise StarletteHTTPException(404, f"no documentation file {name}")
        return FileResponse(FILES / name, headers={"Cache-Control": "public, max-age=86400"})

    @router.get("/openapi.json")
    async def openapi_json() -> RedirectResponse:
        """Where tools look for the document first: it is at /api/openapi.json."""
        return RedirectResponse(OPENAPI_URL, status_code=308)

    return router
