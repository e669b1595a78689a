"""`/api/ready` answers 503 naming the dependency a replica cannot reach, and 200 once it can."""

from __future__ import annotations

import asyncio

import httpx

from tests.conftest import LiveServer, need_service, test_settings
from tests.netproxy import TcpProxy
from tests.polling import eventually


def test_ready_reports_every_dependency_of_a_single_process_server(api):
    r = api.get("/api/ready")
    assert r.status_code == 200, r.text
    assert r.json()["status"] == "ready"
    assert r.json()["checks"] == {"database": "ok", "broker": "ok"}


async def test_a_replica_that_loses_redis_is_not_ready_until_it_is_back(database_url):
    need_service("Redis", "127.0.0.1", 6379)
    link = await TcpProxy("127.0.0.1", 6379).start()
    settings = test_settings(database_url, redis_url=f"redis://127.0.0.1:{link.port}/0")
    # started from a thread: the proxy to Redis runs in this test's event loop
    server = await asyncio.to_thread(LiveServer(settings).start)
    try:
        async with httpx.AsyncClient(base_url=server.url, timeout=10) as c:
            assert (await c.get("/api/ready")).status_code == 200
            link.cut()

            async def not_ready() -> dict | None:  # type: ignore[type-arg]
                r = await c.get("/api/ready")
                return r.json() if r.status_code == 503 else None

            body = await eventually(not_ready, 20, "503 from /api/ready with Redis cut")
            assert body["status"] == "not_ready"
            assert body["checks"]["database"] == "ok"
            assert body["checks"]["broker"].startswith("unreachable")
            # liveness is not readiness: the process still serves and reaches its database
            assert (await c.get("/api/health")).status_code == 200

            link.restore()

            async def ready() -> bool:
                return (await c.get("/api/ready")).status_code == 200

            await eventually(ready, 30, "200 from /api/ready with Redis back")
    finally:
        await asyncio.to_thread(server.stop)
        await link.stop()
