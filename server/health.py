"""`/api/health`: is the server up, and can it reach its database."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from sqlalchemy import text

from server.deps import ServicesDep

router = APIRouter(tags=["health"])


@router.get("/api/health")
async def health(request: Request, services: ServicesDep) -> JSONResponse:
    """200 with the database reachable, 503 when it is not."""
    database = "ok"
    try:
        async with services.engine.connect() as conn:
            await conn.execute(text("SELECT 1"))
    except Exception as err:  # any driver error means unreachable
        database = f"unreachable: {type(err).__name__}"
    ok = database == "ok"
    return JSONResponse(
        {
            "status": "ok" if ok else "degraded",
            "database": database,
            "version": request.app.version,
        },
        status_code=200 if ok else 503,
    )
