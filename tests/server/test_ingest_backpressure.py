"""Storage that falls behind pushes back on the assets instead of piling messages up in memory."""

from __future__ import annotations

import asyncio
import contextlib
import sqlite3
import uuid
from collections.abc import AsyncIterator

import asyncpg
import httpx
import pytest

from server.deps import services_of
from server.realtime import ingest as ingest_module
from tests.conftest import LiveServer, Tenant
from tests.polling import eventually
from tests.server.realtime_client import asset_socket, asset_token, message, uav_sample


@contextlib.asynccontextmanager
async def storage_locked(database_url: str) -> AsyncIterator[None]:
    """Another client holds the stream positions' table: the ingest's writes wait behind it."""
    if database_url.startswith("sqlite"):
        path = database_url.split(":///", 1)[1]
        conn = sqlite3.connect(path, isolation_level=None)
        conn.execute("BEGIN EXCLUSIVE")
        try:
            yield
        finally:
            conn.execute("ROLLBACK")
            conn.close()
        return
    dsn = database_url.replace("postgresql+asyncpg://", "postgresql://")
    pg = await asyncpg.connect(dsn)
    tx = pg.transaction()
    await tx.start()
    await pg.execute("LOCK TABLE asset_streams IN EXCLUSIVE MODE")
    try:
        yield
    finally:
        await tx.rollback()
        await pg.close()


@pytest.mark.slow  # holds the database for a while
async def test_a_congested_ingest_stops_reading_and_loses_nothing(
    live_server: LiveServer, tenant: Tenant, database_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With storage blocked the ingest's queue passes its high-water mark: the asset's socket is
    no longer read (its transport paused, the rest waits in TCP), and once storage is back every
    message is stored once and acknowledged."""
    monkeypatch.setattr(ingest_module, "HIGH_WATER", 40)
    monkeypatch.setattr(ingest_module, "LOW_WATER", 10)
    services = services_of(live_server.app)  # type: ignore[arg-type]
    uav = tenant.create_asset("uav")
    total = 400
    async with asset_socket(live_server.url, asset_token(live_server.url, uav)) as ws:
        received = services.hub.counters.received
        async with storage_locked(database_url):
            for seq in range(1, total + 1):
                await ws.send(message("telemetry", uav_sample(seq), seq=seq))
            await eventually(
                lambda: services.hub.counters.received - received >= 40, 10, "the queue filling"
            )
            session = next(
                s
                for s in services.hub.keeper.sessions.values()
                if s.asset_id == uuid.UUID(uav["id"])
            )
            await eventually(lambda: session._paused, 10, "the socket paused")
            transport = session.sock.transport  # type: ignore[attr-defined]
            assert not transport.is_reading()
            assert services.hub.counters.received - received < total  # the rest waits in TCP

        async def acked_all() -> bool:
            while True:
                got = await asyncio.wait_for(ws.recv(), 30)
                if '"type":"ack"' in got and f'"seq":{total}}}' in got:
                    return True

        assert await asyncio.wait_for(acked_all(), 60)
    assert services.hub.counters.received - received == total
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as api:
        r = await api.get(
            f"/api/v1/assets/{uav['id']}/telemetry",
            params={"start": "2000-01-01T00:00:00Z", "limit": 1000},
        )
    assert r.status_code == 200, r.text
    assert len(r.json()) == total
