"""Two `aerobase server` processes sharing the database and Redis act as one."""

from __future__ import annotations

import asyncio
import base64
import json
import time
import uuid
from collections.abc import Iterator

import httpx
import pytest
import redis.asyncio as aioredis
import websockets

from assetlink.configfile import decrypt_config
from assetlink.dispatch import result
from assetlink.link import Link
from protocol.telemetry_payloads import Position, UavTelemetry
from server.realtime.channels import presence_key
from tests.conftest import Tenant
from tests.polling import eventually
from tests.replicas import REDIS_URL, replicas


@pytest.fixture
def two_servers(database_url: str, tmp_path) -> Iterator[tuple[str, str]]:  # type: ignore[no-untyped-def]
    with replicas(database_url, tmp_path) as started:
        yield tuple(f"http://127.0.0.1:{port}" for port, _ in started)  # type: ignore[misc]


@pytest.mark.slow
async def test_two_processes_act_as_one(two_servers, api, superuser_email, tmp_path):
    url_a, url_b = two_servers
    tenant = Tenant(
        api, superuser_email, "scale"
    )  # built through the session's server: same database
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    link = Link(url_b, cfg.name, cfg.secret, tmp_path / "link.db", seed=7)
    executed = []

    async def check(request):  # type: ignore[no-untyped-def]
        executed.append(request.id)
        return result("succeeded", "ready")

    link.on_command("check_availability", check)
    await link.start()
    try:
        await link.wait_connected(20)
        # a second login of that asset on A is refused while it is connected to B
        async with httpx.AsyncClient(base_url=url_a) as a:
            r = await a.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
            assert r.status_code == 409 and r.json()["error"]["code"] == "session_active"
        # an operator on A receives live telemetry of the asset connected to B
        ws_a = url_a.replace("http", "ws") + f"/ws/operator?token={tenant.tokens['viewer']}"
        async with websockets.connect(ws_a) as op:
            await op.send(
                json.dumps(
                    {
                        "v": 1,
                        "type": "subscribe",
                        "id": "1b7e1b2e-0000-4000-8000-000000000001",
                        "seq": 0,
                        "ts": 0,
                        "payload": {"asset_ids": [asset["id"]]},
                    }
                )
            )
            got = None
            for i in range(100):  # keep sending until the subscription (async in Redis) is in place
                await link.send_telemetry(
                    UavTelemetry(
                        position=Position(lat=41.0, lon=-8.6, alt_msl_m=120, alt_rel_m=float(i))
                    )
                )
                try:
                    got = json.loads(await asyncio.wait_for(op.recv(), 0.2))
                    break
                except TimeoutError:
                    continue
            assert (
                got is not None
                and got["type"] == "telemetry"
                and got["payload"]["asset_id"] == asset["id"]
            )
            # a command posted to A reaches the asset on B and its result comes back (to A's operator too)
            async with httpx.AsyncClient(base_url=url_a) as a:
                r = await a.post(
                    f"/api/v1/assets/{asset['id']}/commands",
                    json={"name": "check_availability"},
                    headers=tenant.h("operator"),
                )
                assert r.status_code == 202, r.text
                cid = r.json()["id"]
                deadline = time.monotonic() + 20
                status = None
                while time.monotonic() < deadline:
                    status = (
                        await a.get(f"/api/v1/commands/{cid}", headers=tenant.h("viewer"))
                    ).json()["status"]
                    if status == "succeeded":
                        break
                    await asyncio.sleep(0.05)
                assert status == "succeeded"
            while True:
                msg = json.loads(await asyncio.wait_for(op.recv(), 10))
                if msg["type"] == "command_result" and msg.get("re") == cid:
                    break
        assert executed and len(executed) == 1
    finally:
        await link.stop()


@pytest.mark.slow
def test_two_processes_sharing_a_schedule_start_its_run_exactly_once(
    two_servers, api, superuser_email
):
    from datetime import UTC, datetime, timedelta

    from tests.conftest import wait_for

    url_a, url_b = two_servers
    tenant = Tenant(api, superuser_email, "sched")
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    mission = api.post(
        "/api/v1/missions",
        headers=tenant.h("operator"),
        json={
            "name": "m",
            "items": [{"command": 22, "lat": 41.178, "lon": -8.598, "alt": 20}, {"command": 20}],
        },
    ).json()
    ids = {"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]}
    with httpx.Client(base_url=url_a) as a, httpx.Client(base_url=url_b) as b:
        due = (datetime.now(UTC) + timedelta(seconds=2)).isoformat()
        s = a.post(
            "/api/v1/schedules",
            headers=tenant.h("operator"),
            json={**ids, "name": "dawn patrol", "kind": "once", "at": due},
        ).json()
        # fired and disabled in the same transaction: after this no process can fire it again
        wait_for(
            lambda: (
                not b.get(f"/api/v1/schedules/{s['id']}", headers=tenant.h("viewer")).json()[
                    "enabled"
                ]
            ),
            30,
            what="the schedule to fire",
        )
        runs_a = [
            r
            for r in a.get("/api/v1/runs", headers=tenant.h("viewer")).json()
            if r["schedule_id"] == s["id"]
        ]
        runs_b = [
            r
            for r in b.get("/api/v1/runs", headers=tenant.h("viewer")).json()
            if r["schedule_id"] == s["id"]
        ]
    assert len(runs_a) == 1 and [r["id"] for r in runs_a] == [r["id"] for r in runs_b]


@pytest.mark.slow
async def test_a_presence_key_that_lapsed_is_claimed_again_by_the_live_connection(
    two_servers, api, superuser_email, tmp_path
):
    """A replica whose loop stalls past the presence TTL (a loaded machine) finds its key gone:
    nobody else holds it, so its connection is still the asset's one and keeps it (before, it
    closed its own asset with 4409 "another connection took over", seen under bench load)."""
    url_a, _ = two_servers
    tenant = Tenant(api, superuser_email, "lapse")
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    link = Link(url_a, cfg.name, cfg.secret, tmp_path / "link.db", seed=11)
    r = aioredis.from_url(REDIS_URL)
    key = "aerobase:" + presence_key(uuid.UUID(asset["id"]))
    await link.start()
    try:
        await link.wait_connected(20)
        owner = await eventually(lambda: r.get(key), 10, "the asset's presence key")
        await r.delete(key)  # what the TTL does when the refresh comes too late
        assert await eventually(lambda: r.get(key), 10, "the presence key claimed again") == owner
        assert link.connected and link.stats.reconnects == 0
    finally:
        await link.stop()
        await r.aclose()


async def test_the_redis_broker_takes_more_concurrent_publishes_than_its_pool_has_connections():
    """Every asset session publishes each message: 200 UAVs at 10 Hz put well over 100 publishes
    in flight at once, which redis-py's default pool refused ("Too many connections"), failing
    the sockets (bench/scale.py through nginx). Callers now wait for a connection."""
    from server.realtime.broker import POOL_SIZE, RedisBroker
    from tests.conftest import need_service

    need_service("Redis", "127.0.0.1", 6379)
    broker = RedisBroker(REDIS_URL, prefix=f"pool-{uuid.uuid4().hex[:8]}:")
    await broker.start()
    received: list[dict] = []  # type: ignore[type-arg]
    broker.subscribe("flood", received.append)
    try:

        async def echoed() -> bool:  # the subscription is made by a task of its own
            await broker.publish("flood", {"probe": True})
            return bool(received)

        await eventually(echoed, 5, "the subscription in place", interval=0.05)
        count = 4 * POOL_SIZE
        await asyncio.gather(*(broker.publish("flood", {"n": n}) for n in range(count)))

        def numbered() -> list[int]:
            return sorted(m["n"] for m in received if "n" in m)

        await eventually(lambda: len(numbered()) >= count, 10, "every message back")
        assert numbered() == list(range(count))
    finally:
        await broker.close()
