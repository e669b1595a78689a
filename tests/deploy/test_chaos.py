"""A replica dies mid-run: kill -9 the server process that holds a flying run's lease, behind the
proxy, with a second replica beside it; the run completes on the survivor.

The native topology of docker-compose.yml: nginx (deploy/nginx/aerobase.conf) in front of two
`aerobase server` processes on their own PostgreSQL database and Redis; the simulated world and
both daemons connect through the proxy, as they would in a deployment.
"""

from __future__ import annotations

import asyncio
import json
import re
import signal
import sqlite3
import uuid
from collections import Counter
from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest
from sqlalchemy import text
from sqlalchemy.ext.asyncio import create_async_engine

from server import migrate
from server.kit.db import make_engine, make_sessionmaker
from server.kit.security import Passwords
from server.organizations.service import create_user
from tests.conftest import PG_URL_DEFAULT, SUPERUSER_PASSWORD, Tenant, need_service
from tests.e2e.harness import FINAL, platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE
from tests.polling import eventually
from tests.replicas import proxy, replicas

pytestmark = pytest.mark.slow

MOTION = {"open", "close", "open_panels", "close_panels", "lift_up", "lift_down", "start_mission"}


@pytest.fixture
async def own_database() -> AsyncIterator[str]:
    """A PostgreSQL database of this test alone (several replicas need PostgreSQL; the session's
    own server must not drive this test's runs), migrated, with a superuser."""
    need_service("PostgreSQL", "127.0.0.1", 5432)
    name = f"chaos_{uuid.uuid4().hex[:12]}"
    admin = create_async_engine(PG_URL_DEFAULT, isolation_level="AUTOCOMMIT")
    async with admin.connect() as conn:
        await conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = PG_URL_DEFAULT.rsplit("/", 1)[0] + f"/{name}"
    try:
        await asyncio.to_thread(migrate.upgrade, url)
        engine = make_engine(url)
        async with make_sessionmaker(engine)() as db:
            await create_user(
                db,
                Passwords(1, 8192, 1),
                email="root@chaos.test",
                password=SUPERUSER_PASSWORD,
                is_superuser=True,
            )
            await db.commit()
        await engine.dispose()
        yield url
    finally:
        async with admin.connect() as conn:
            await conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        await admin.dispose()


async def _lease_owner(url: str, run_id: str) -> str | None:
    engine = create_async_engine(url)
    try:
        async with engine.connect() as conn:
            row = await conn.execute(
                text("SELECT lease_owner FROM runs WHERE id = :id"), {"id": uuid.UUID(run_id)}
            )
            return row.scalar_one_or_none()
    finally:
        await engine.dispose()


def _ledger(state_file: Path) -> Counter[str]:
    """The commands a daemon executed, by name, from its link's command ledger."""
    with sqlite3.connect(state_file) as db:
        return Counter(name for (name,) in db.execute("SELECT name FROM commands"))


async def test_killing_the_lease_holder_mid_flight_the_run_completes_on_the_other_replica(
    own_database, tmp_path
):
    with replicas(own_database, tmp_path) as servers:
        nodes = {}
        async with httpx.AsyncClient() as c:
            for port, proc in servers:
                health = (await c.get(f"http://127.0.0.1:{port}/api/health")).json()
                nodes[f"runs-{health['node']}"] = (port, proc)
        with proxy([port for port, _ in servers], tmp_path) as url:
            with httpx.Client(base_url=url, timeout=30) as api:
                tenant = Tenant(api, "root@chaos.test", "chaos")
                async with platform(url, tenant, tmp_path, precland={}, speed=2.5) as p:
                    run_id = await p.start_run()
                    await p.wait_state(run_id, ("flying",), 90)
                    await eventually(
                        lambda: p.world.base.pad_mass_g == 0, 60, "the UAV to take off"
                    )
                    holder = await _lease_owner(own_database, run_id)
                    assert holder in nodes, (holder, nodes)
                    port, proc = nodes.pop(holder)
                    proc.send_signal(signal.SIGKILL)
                    proc.wait()
                    (survivor,) = nodes

                    body = await p.wait_state(run_id, FINAL, 240)
                    assert body["state"] == "completed", (
                        body["reason"],
                        [(t["to_state"], t["reason"]) for t in body["timeline"]],
                        {"pad_distance_m": round(p.copter.pad_distance(), 3)},
                    )
                    steps = [
                        t["to_state"] for t in body["timeline"] if t["cause"] != "lease_takeover"
                    ]
                    assert steps.count("flying") == 1  # resumed where it stood
                    takeovers = [t for t in body["timeline"] if t["cause"] == "lease_takeover"]
                    assert len(takeovers) == 1 and survivor in takeovers[0]["reason"], takeovers
                    assert await _lease_owner(own_database, run_id) in (survivor, None)

                    # every durable message of the agent was acked (acks follow storage)
                    uav_link = p.agent.link
                    assert await uav_link.flush(60)
                    assert uav_link.stats.dropped == 0
                # every log line of a run carries its id, every request line the proxy's request id
                lines = [
                    json.loads(line)
                    for line in (tmp_path / "servers.log").read_text().splitlines()
                    if line.startswith("{")
                ]
                moves = [x for x in lines if x.get("run_id") == run_id and "->" in x["event"]]
                assert len(moves) >= len(WHOLE_SEQUENCE), moves
                served = [x for x in lines if x.get("logger") == "aerobase.access"]
                assert served and all(
                    re.fullmatch(r"[0-9a-f]{32}", x["request_id"]) for x in served
                )
                # each motion command ran once on its daemon, whichever replica delivered it
                for ledger in (_ledger(tmp_path / "base.db"), _ledger(tmp_path / "agent.db")):
                    twice = {n: c for n, c in ledger.items() if n in MOTION and c > 1}
                    assert not twice, ledger
