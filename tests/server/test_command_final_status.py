"""A command's final status is final, whatever a concurrent writer holds in memory (issue 14's
succeeded -> timed_out seen once in ~10 runs: the deadline sweep read the command as in_progress,
the asset's result committed `succeeded`, then the sweep wrote `timed_out` over it)."""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator

import pytest
from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker, create_async_engine

from server.commands import service as commands
from server.commands.models import AssetCommand, CommandStatusChange
from tests.conftest import Tenant


@pytest.fixture
async def sessions(database_url: str) -> AsyncIterator[async_sessionmaker[AsyncSession]]:
    """Sessions on the live server's database, on an engine of the test's own."""
    engine = create_async_engine(database_url)
    yield async_sessionmaker(engine, expire_on_commit=False)
    await engine.dispose()


def queued_command(api, tenant: Tenant) -> uuid.UUID:
    """A real command row, queued over the API for a fresh UAV."""
    uav = tenant.create_asset("uav")
    r = api.post(
        f"/api/v1/assets/{uav['id']}/commands",
        headers=tenant.h("operator"),
        json={"name": "check_availability", "timeout_s": 30},
    )
    assert r.status_code == 202, r.text
    return uuid.UUID(r.json()["id"])


async def test_a_sweep_holding_a_stale_command_cannot_overwrite_a_committed_success(
    api, tenant: Tenant, sessions
):
    cid = queued_command(api, tenant)
    async with sessions() as sweep, sessions() as ingest:
        stale = await sweep.get(AssetCommand, cid)  # the sweep reads it while it is open
        assert stale is not None and stale.status == "queued"
        fresh = await ingest.get(AssetCommand, cid)
        assert fresh is not None
        await commands.apply_result(
            ingest, cid, fresh.asset_id, {"status": "succeeded", "reason": "available"}
        )
        await ingest.commit()
        changed = await commands.set_status(sweep, stale, "timed_out", "no final answer")
        await sweep.commit()
        assert changed is False
        assert stale.status == "succeeded"  # the object in hand now says what is stored
    async with sessions() as check:
        stored = await check.get(AssetCommand, cid)
        assert stored is not None and stored.status == "succeeded"
        history = await check.scalars(
            select(CommandStatusChange.status).where(CommandStatusChange.command_id == cid)
        )
        assert "timed_out" not in list(history)


async def test_a_result_after_a_final_status_changes_nothing(api, tenant: Tenant, sessions):
    cid = queued_command(api, tenant)
    async with sessions() as db:
        cmd = await db.get(AssetCommand, cid)
        assert cmd is not None
        assert await commands.set_status(db, cmd, "timed_out", "deadline") is True
        await db.commit()
        assert not await commands.apply_result(db, cid, cmd.asset_id, {"status": "succeeded"})
        await db.commit()
        assert (await db.get(AssetCommand, cid)).status == "timed_out"  # type: ignore[union-attr]
