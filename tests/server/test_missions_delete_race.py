"""A mission's DELETE racing the run engine on PostgreSQL: a clear 409, never a deadlock's 500.

The engine locks a run, updates it, and updates it again in the same transaction; the second
UPDATE re-checks the run's foreign key (KEY SHARE on the mission, because the row version is the
transaction's own). A DELETE of the mission that had meanwhile locked the mission and waited in
its RESTRICT check for the run's row made a cycle: PostgreSQL aborted the DELETE (HTTP 500).
"""

from __future__ import annotations

import asyncio
import threading
import uuid
from datetime import UTC, datetime

import asyncpg
import httpx
import pytest

from server.kit.db import make_engine, make_sessionmaker
from server.runs import repository as runs
from tests.conftest import (
    LiveServer,
    Tenant,
    _reset_postgres,
    create_superuser,
    need_service,
    test_settings,
    wait_for,
)
from tests.server.test_missions_api import waypoints

PG = "postgresql://postgres@127.0.0.1:5432"
URL = "postgresql+asyncpg://postgres@127.0.0.1:5432/aerobase_mission_race"


@pytest.fixture(scope="module")
def server() -> LiveServer:
    need_service("PostgreSQL", "127.0.0.1", 5432)

    async def make_db() -> None:
        conn = await asyncpg.connect(f"{PG}/postgres")
        await conn.execute("DROP DATABASE IF EXISTS aerobase_mission_race WITH (FORCE)")
        await conn.execute("CREATE DATABASE aerobase_mission_race")
        await conn.close()

    asyncio.run(make_db())
    _reset_postgres(URL)
    from server import migrate

    migrate.upgrade(URL)
    live = LiveServer(test_settings(URL)).start()
    yield live
    live.stop()


def _waiting_on_a_lock() -> bool:
    async def query() -> bool:
        conn = await asyncpg.connect(f"{PG}/aerobase_mission_race")
        try:
            n = await conn.fetchval(
                "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'"
                " AND query ILIKE 'DELETE FROM missions%'"
            )
            return bool(n)
        finally:
            await conn.close()

    return asyncio.run(query())


@pytest.mark.slow  # a server of its own on a database of its own
def test_deleting_a_mission_while_the_engine_holds_its_run_answers_409(server: LiveServer):
    email = f"root-{uuid.uuid4().hex[:8]}@aerobase.test"
    asyncio.run(create_superuser(URL, email))
    with httpx.Client(base_url=server.url, timeout=30) as api:
        tenant = Tenant(api, email)
        mission = api.post(
            "/api/v1/missions",
            json={"name": "raced", "items": waypoints()},
            headers=tenant.h("operator"),
        ).json()
        base = tenant.create_asset("landing_base")
        uav = tenant.create_asset("uav", base_id=base["id"])
        run = api.post(
            "/api/v1/runs",
            json={"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]},
            headers=tenant.h("operator"),
        )
        assert run.status_code == 201, run.text
        run_id = uuid.UUID(run.json()["id"])

        answer: list[httpx.Response] = []
        deleting = threading.Thread(
            target=lambda: answer.append(
                api.delete(f"/api/v1/missions/{mission['id']}", headers=tenant.h("operator"))
            )
        )

        async def engine_transaction() -> None:
            # what the engine does in one tick: lock the run, write it, write it again
            engine = make_engine(URL)
            try:
                async with make_sessionmaker(engine)() as db, db.begin():
                    held = await runs.lock(db, run_id)
                    assert held is not None
                    held.lease_until = datetime.now(UTC)
                    await db.flush()
                    deleting.start()
                    # the DELETE either answers or waits on a lock; then the engine writes again
                    await asyncio.to_thread(
                        wait_for,
                        lambda: answer or _waiting_on_a_lock(),
                        20,
                        what="the DELETE to answer or wait",
                    )
                    held.lease_owner = "engine-under-test"
                    await db.flush()
            finally:
                await engine.dispose()

        asyncio.run(engine_transaction())
        deleting.join(30)
        assert answer, "the DELETE did not answer"
        r = answer[0]
        assert r.status_code == 409, r.text
        assert r.json()["error"]["code"] == "mission_in_use"
        assert (
            api.get(f"/api/v1/missions/{mission['id']}", headers=tenant.h("viewer")).status_code
            == 200
        )
