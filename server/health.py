"""What operations tools read: `/api/health` (liveness: the process serves and reaches its
database), `/api/ready` (readiness: every dependency this replica uses answers — database, broker,
telemetry store) and `/metrics` (Prometheus, this process; see `server/kit/metrics.py`)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Literal

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from pydantic import BaseModel, Field
from sqlalchemy import text

from server.deps import ServicesDep
from server.kit.metrics import REGISTRY
from server.services import Services
from server.telemetry.influx import InfluxTelemetryStore
from server.video.janus import JanusGateway

router = APIRouter(tags=["health"])

CHECK_TIMEOUT_S = 2.0


async def _database(services: Services) -> None:
    async with services.engine.connect() as conn:
        await conn.execute(text("SELECT 1"))


async def _check(probe: Callable[[], Awaitable[None]]) -> str:
    """'ok', or 'unreachable: <why>' when the probe fails or takes over CHECK_TIMEOUT_S."""
    try:
        async with asyncio.timeout(CHECK_TIMEOUT_S):
            await probe()
    except TimeoutError:
        return f"unreachable: no answer within {CHECK_TIMEOUT_S:g} s"
    except Exception as err:  # any driver or network error means unreachable
        return f"unreachable: {type(err).__name__}: {err}"[:200]
    return "ok"


class HealthOut(BaseModel):
    """Liveness: this process serves and reaches its database."""

    status: Literal["ok", "degraded"] = Field(
        description="degraded when the database is not reached"
    )
    database: str = Field(description='"ok" or "unreachable: <why>"', examples=["ok"])
    version: str = Field(description="the server's version", examples=["0.1.0"])
    node: str = Field(description="this replica's id (for logs)", examples=["a1b2c3d4"])


class ReadyOut(BaseModel):
    """Readiness: every dependency this replica uses answers."""

    status: Literal["ready", "not_ready"]
    checks: dict[str, str] = Field(
        description='each dependency: "ok" or "unreachable: <why>"',
        examples=[{"database": "ok", "broker": "ok"}],
    )
    version: str = Field(description="the server's version", examples=["0.1.0"])


@router.get(
    "/api/health",
    response_model=HealthOut,
    operation_id="getHealth",
    responses={503: {"model": HealthOut, "description": "the database is not reached"}},
)
async def health(request: Request, services: ServicesDep) -> JSONResponse:
    """200 with the database reachable, 503 when it is not."""
    database = await _check(lambda: _database(services))
    ok = database == "ok"
    return JSONResponse(
        {
            "status": "ok" if ok else "degraded",
            "database": database,
            "version": request.app.version,
            "node": services.hub.node,
        },
        status_code=200 if ok else 503,
    )


@router.get(
    "/api/ready",
    response_model=ReadyOut,
    operation_id="getReadiness",
    responses={503: {"model": ReadyOut, "description": "a dependency does not answer"}},
)
async def ready(request: Request, services: ServicesDep) -> JSONResponse:
    """200 when the database, the broker and (when configured) InfluxDB and Janus all answer; 503 naming
    the one that does not, so a proxy sends no traffic to a replica that cannot serve it."""
    probes: dict[str, Callable[[], Awaitable[None]]] = {
        "database": lambda: _database(services),
        "broker": services.broker.ping,
    }
    if isinstance(services.telemetry, InfluxTelemetryStore):
        probes["influxdb"] = services.telemetry.ping
    if isinstance(services.video, JanusGateway):
        probes["janus"] = services.video.ping
    results = await asyncio.gather(*(_check(p) for p in probes.values()))
    checks = dict(zip(probes, results, strict=True))
    ok = all(v == "ok" for v in checks.values())
    return JSONResponse(
        {
            "status": "ready" if ok else "not_ready",
            "checks": checks,
            "version": request.app.version,
        },
        status_code=200 if ok else 503,
    )


@router.get("/metrics", include_in_schema=False)
async def prometheus() -> Response:
    """Prometheus text exposition of this process's metrics (scraped on the internal network; the
    proxy does not pass it)."""
    return Response(generate_latest(REGISTRY), media_type=CONTENT_TYPE_LATEST)
