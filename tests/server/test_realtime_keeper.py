"""The process's upkeep of its asset sockets (server/realtime/keeper.py), over real sockets.

Each job is run once in the server's own event loop (as its timer would) after the state it reacts
to was made behind the server's back: an ended login session nobody announced, a command queued
without a nudge, a presence claim lost or taken.
"""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import Awaitable, Callable
from datetime import timedelta
from typing import Any

from sqlalchemy import insert, update

from server.auth.models import AuthSession
from server.commands.models import AssetCommand
from server.deps import services_of
from server.kit.db import make_engine, make_sessionmaker
from server.kit.time import utcnow
from server.realtime.channels import presence_key
from server.realtime.keeper import PRESENCE_TTL_S, AssetKeeper
from server.services import Services
from tests.conftest import LiveServer, Tenant
from tests.polling import eventually
from tests.server.realtime_client import asset_socket, asset_token, close_code, next_of


def _services(live: LiveServer) -> Services:
    return services_of(live.app)  # type: ignore[arg-type]


async def _in_server(live: LiveServer, job: Callable[[AssetKeeper], Awaitable[Any]]) -> Any:
    """Run `job(keeper)` in the server's event loop (its thread) and wait for it."""
    services = _services(live)
    loop = services.ingest._task.get_loop()  # type: ignore[union-attr]
    future = asyncio.run_coroutine_threadsafe(job(services.hub.keeper), loop)
    return await asyncio.wrap_future(future)


async def _connected(live: LiveServer, asset: dict[str, Any]) -> Any:
    """An asset socket past hello/welcome, and kept by the keeper."""
    keeper = _services(live).hub.keeper
    before = set(keeper.sessions)
    cm = asset_socket(live.url, asset_token(live.url, asset))
    ws = await cm.__aenter__()  # past hello/welcome
    await eventually(lambda: set(keeper.sessions) - before, 10, "the keeper keeps the socket")
    return cm, ws


def _columns(row: Any) -> dict[str, Any]:
    return {
        c.key: getattr(row, c.key) for c in row.__table__.columns if getattr(row, c.key) is not None
    }


async def _db(database_url: str, statement: Any) -> None:
    engine = make_engine(database_url)
    try:
        async with make_sessionmaker(engine)() as db:
            await db.execute(statement)
            await db.commit()
    finally:
        await engine.dispose()


async def test_an_ended_login_session_nobody_announced_closes_its_socket(
    live_server: LiveServer, tenant: Tenant, database_url: str
) -> None:
    asset = tenant.create_asset("uav")
    cm, ws = await _connected(live_server, asset)
    try:
        await _in_server(live_server, lambda k: k.touch_sessions())  # alive: nothing happens
        await ws.ping()
        ended = (
            update(AuthSession)
            .where(AuthSession.asset_id == uuid.UUID(asset["id"]), AuthSession.ended_at.is_(None))
            .values(ended_at=utcnow(), end_reason="test")
        )
        await _db(database_url, ended)  # ended behind the server's back: no announcement
        await _in_server(live_server, lambda k: k.touch_sessions())
        assert await close_code(ws) == 4001
    finally:
        await cm.__aexit__(None, None, None)


async def test_a_command_queued_without_a_nudge_is_delivered_by_the_sweep(
    live_server: LiveServer, tenant: Tenant, database_url: str
) -> None:
    asset = tenant.create_asset("uav")
    cm, ws = await _connected(live_server, asset)
    try:
        command = AssetCommand(
            id=uuid.uuid4(),
            organization_id=uuid.UUID(tenant.id),
            asset_id=uuid.UUID(asset["id"]),
            name="check_availability",
            params={},
            deadline=utcnow() + timedelta(minutes=5),
            created_by="test",
        )
        await _db(database_url, insert(AssetCommand).values(**_columns(command)))
        await _in_server(live_server, lambda k: k.sweep_commands())
        delivered = await next_of(ws, "command")
        assert delivered["id"] == str(command.id)
    finally:
        await cm.__aexit__(None, None, None)


async def test_a_lapsed_presence_is_claimed_again_and_a_taken_one_evicts(
    live_server: LiveServer, tenant: Tenant
) -> None:
    asset = tenant.create_asset("uav")
    broker = _services(live_server).broker
    key = presence_key(uuid.UUID(asset["id"]))
    cm, ws = await _connected(live_server, asset)
    try:
        owner = broker._claims[key][0]  # type: ignore[attr-defined]

        async def lapse(keeper: AssetKeeper) -> None:
            del broker._claims[key]  # type: ignore[attr-defined]
            await keeper.refresh_presence()

        await _in_server(live_server, lapse)
        assert broker._claims[key][0] == owner  # type: ignore[attr-defined]
        await ws.ping()  # still open

        async def take(keeper: AssetKeeper) -> None:
            await broker.release(key, owner)
            assert await broker.claim(key, "another-replica:1", PRESENCE_TTL_S) is None
            await keeper.refresh_presence()

        await _in_server(live_server, take)
        assert await close_code(ws) == 4409
    finally:
        await cm.__aexit__(None, None, None)
