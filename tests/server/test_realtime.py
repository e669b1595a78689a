"""The realtime core over real sockets: the real link (protocol/link.py) against the real server."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import time
import uuid

import httpx
import pytest
import websockets

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from assetlink.settings import LinkSettings, Traffic
from protocol.messages import EventPayload
from protocol.telemetry_payloads import Battery, Position, UavTelemetry
from server.deps import services_of
from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import eventually


def _cfg(asset: dict, password: str = "asset-password-123"):  # type: ignore[no-untyped-def]
    return decrypt_config(base64.b64decode(asset["config_file"]), password)


def _sample(i: int) -> UavTelemetry:
    return UavTelemetry(
        position=Position(lat=41.0 + i * 1e-6, lon=-8.6, alt_msl_m=120.0, alt_rel_m=float(i % 50)),
        battery=Battery(percent=90.0, voltage_v=16.4, current_a=1.0),
        armed=False,
    )


async def _count(server_url: str, tenant: Tenant, asset_id: str) -> list:
    async with httpx.AsyncClient(base_url=server_url) as c:
        r = await c.get(
            f"/api/v1/assets/{asset_id}/telemetry",
            params={"start": "2000-01-01T00:00:00Z", "end": "2100-01-01T00:00:00Z"},
            headers=tenant.h("viewer"),
        )
        assert r.status_code == 200, r.text
        return list(r.json())


async def test_telemetry_is_stored_acked_and_reaches_operators(
    live_server, tenant: Tenant, tmp_path
):
    asset = tenant.create_asset("uav")
    cfg = _cfg(asset)
    url = live_server.url.replace("http", "ws") + f"/ws/operator?token={tenant.tokens['viewer']}"
    async with websockets.connect(url) as op:
        await op.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "subscribe",
                    "id": "6f1c3a3e-58a4-4d1e-9f55-000000000001",
                    "seq": 0,
                    "ts": 0,
                    "payload": {"asset_ids": [asset["id"]]},
                }
            )
        )
        link = Link(live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=1)
        await link.start()
        try:
            await link.wait_connected(15)
            for i in range(20):
                await link.send_telemetry(_sample(i))
            await link.send_event(EventPayload(name="armed", message="motors armed"))
            assert await link.flush(15)
            got = []
            while len(got) < 21:
                got.append(json.loads(await asyncio.wait_for(op.recv(), 10)))
        finally:
            await link.stop()
    kinds = [m["type"] for m in got]
    assert kinds.count("telemetry") == 20 and kinds.count("event") == 1
    assert all(m["payload"]["asset_id"] == asset["id"] for m in got)
    rows = await _count(live_server.url, tenant, asset["id"])
    assert len(rows) == 20
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        latest = (
            await c.get(
                f"/api/v1/assets/{asset['id']}/telemetry/latest", headers=tenant.h("viewer")
            )
        ).json()
        assert latest["position.alt_rel_m"] == 19.0
        events = (
            await c.get(f"/api/v1/assets/{asset['id']}/events", headers=tenant.h("viewer"))
        ).json()
        assert [e["name"] for e in events] == ["armed"]


async def test_flush_waits_for_what_was_queued_not_for_a_stream_that_never_stops(
    live_server, tenant: Tenant, tmp_path
):
    """A flying UAV queues telemetry all the time, so its outbox is never empty: flush waits
    until what was queued before it is stored and acked (the e2e link-cut test flushed under
    load and timed out waiting for an empty outbox)."""
    cfg = _cfg(tenant.create_asset("uav"))
    link = Link(live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=1)
    await link.start()
    stop = asyncio.Event()

    async def stream() -> None:
        i = 100
        while not stop.is_set():
            await link.send_telemetry(_sample(i))
            i += 1
            await asyncio.sleep(0)

    try:
        await link.wait_connected(15)
        for i in range(20):
            await link.send_telemetry(_sample(i))
        streaming = asyncio.create_task(stream())
        try:
            assert await link.flush(15)
            assert link.stats.acked >= 20 and link.stats.queued > 0  # still streaming
        finally:
            stop.set()
            await streaming
    finally:
        await link.stop()


async def test_operator_cannot_subscribe_to_another_organisation(
    live_server, tenant: Tenant, api, superuser_email
):
    other = Tenant(api, superuser_email, "other")
    foreign = other.create_asset("uav")
    url = live_server.url.replace("http", "ws") + f"/ws/operator?token={tenant.tokens['admin']}"
    async with websockets.connect(url) as op:
        await op.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "subscribe",
                    "id": "6f1c3a3e-58a4-4d1e-9f55-000000000002",
                    "seq": 0,
                    "ts": 0,
                    "payload": {"asset_ids": [foreign["id"]]},
                }
            )
        )
        reply = json.loads(await asyncio.wait_for(op.recv(), 10))
    assert reply["type"] == "error" and reply["payload"]["code"] == "not_found"


async def test_command_round_trip_and_status_history(live_server, tenant: Tenant, tmp_path):
    asset = tenant.create_asset("landing_base")
    cfg = _cfg(asset)
    link = Link(
        live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", agent="base_station", seed=2
    )
    calls = []

    async def check(request):  # type: ignore[no-untyped-def]
        calls.append(request.id)
        from assetlink.dispatch import result

        return result("succeeded", "all conditions met", {"wind_mps": 3.0})

    link.on_command("check_availability", check)
    await link.start()
    try:
        await link.wait_connected(15)
        async with httpx.AsyncClient(base_url=live_server.url) as c:
            r = await c.post(
                f"/api/v1/assets/{asset['id']}/commands",
                json={"name": "check_availability"},
                headers=tenant.h("operator"),
            )
            assert r.status_code == 202
            cid = r.json()["id"]

            async def final():  # type: ignore[no-untyped-def]
                body = (await c.get(f"/api/v1/commands/{cid}", headers=tenant.h("viewer"))).json()
                return body if body["status"] == "succeeded" else None

            body = await eventually(final, what="command result")
    finally:
        await link.stop()
    assert [h["status"] for h in body["history"]] == ["queued", "sent", "succeeded"]
    assert body["result"] == {"wind_mps": 3.0} and len(calls) == 1


async def test_unanswered_command_times_out(live_server, tenant: Tenant):
    asset = tenant.create_asset("uav")
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        cid = (
            await c.post(
                f"/api/v1/assets/{asset['id']}/commands",
                json={"name": "land", "timeout_s": 1},
                headers=tenant.h("operator"),
            )
        ).json()["id"]

        async def timed_out():  # type: ignore[no-untyped-def]
            body = (await c.get(f"/api/v1/commands/{cid}", headers=tenant.h("viewer"))).json()
            return body if body["status"] == "timed_out" else None

        body = await eventually(timed_out, what="timed_out")
    assert "deadline" in body["reason"]


async def test_duplicate_asset_connection_is_closed_4409(live_server, tenant: Tenant, tmp_path):
    asset = tenant.create_asset("uav")
    cfg = _cfg(asset)
    link = Link(live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=3)
    await link.start()
    try:
        await link.wait_connected(15)
        async with httpx.AsyncClient(base_url=live_server.url) as c:
            token = (
                await c.post(
                    "/api/v1/assets/login",
                    json={"name": cfg.name, "secret": cfg.secret, "force": False},
                )
            ).status_code
            assert token == 409  # the live link's session blocks a second login
        # a second socket with the link's own token: refused with 4409
        own = link._token.access_token
        ws_url = live_server.url.replace("http", "ws") + "/ws/asset"
        async with websockets.connect(
            ws_url, additional_headers={"Authorization": f"Bearer {own}"}
        ) as ws:
            with pytest.raises(websockets.ConnectionClosed) as info:
                await asyncio.wait_for(ws.recv(), 10)
        assert info.value.rcvd.code == 4409
    finally:
        await link.stop()


async def test_bad_input_gets_errors_and_oversize_closes_1009(live_server, tenant: Tenant):
    asset = tenant.create_asset("uav")
    cfg = _cfg(asset)
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        token = (
            await c.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
        ).json()["access_token"]
    ws_url = live_server.url.replace("http", "ws") + "/ws/asset"
    async with websockets.connect(
        ws_url, additional_headers={"Authorization": f"Bearer {token}"}, max_size=None
    ) as ws:
        await ws.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "hello",
                    "id": "6f1c3a3e-58a4-4d1e-9f55-000000000003",
                    "seq": 0,
                    "ts": 0,
                    "payload": {
                        "stream": "6f1c3a3e-58a4-4d1e-9f55-0000000000aa",
                        "agent": "asset_agent",
                        "version": "t",
                    },
                }
            )
        )
        assert json.loads(await ws.recv())["type"] == "welcome"
        for bad in (
            "{not json",
            json.dumps(
                {"v": 1, "type": "telemetry", "id": "x", "seq": "a", "ts": 0, "payload": {}}
            ),
            json.dumps(
                {
                    "v": 1,
                    "type": "teleport",
                    "id": "6f1c3a3e-58a4-4d1e-9f55-000000000004",
                    "seq": 1,
                    "ts": 0,
                    "payload": {},
                }
            ),
        ):
            await ws.send(bad)
            reply = json.loads(await asyncio.wait_for(ws.recv(), 10))
            assert reply["type"] == "error", reply
        await ws.send("x" * (1024 * 1024 + 10))
        with pytest.raises(websockets.ConnectionClosed) as info:
            while True:
                await asyncio.wait_for(ws.recv(), 10)
        assert info.value.rcvd.code == 1009


@pytest.mark.slow
async def test_link_cut_and_server_restart_lose_nothing_and_duplicate_nothing(
    database_url, tenant: Tenant, tmp_path
):
    """10 Hz telemetry; the server is stopped and restarted mid-stream; the store holds each sample once."""
    asset = tenant.create_asset("uav")
    cfg = _cfg(asset)
    server = LiveServer(test_settings(database_url)).start()
    port = server.port
    link = Link(
        server.url,
        cfg.name,
        cfg.secret,
        tmp_path / "link.db",
        LinkSettings(backoff_min=0.05, backoff_max=0.3),
        seed=4,
    )
    await link.start()
    sent = 0
    try:
        await link.wait_connected(15)
        for _ in range(15):
            await link.send_telemetry(_sample(sent))
            sent += 1
            await asyncio.sleep(0.1)  # the 10 Hz rate itself, not synchronisation
        await asyncio.to_thread(server.stop)
        for _ in range(15):  # sent while the server is down: queued on disk
            await link.send_telemetry(_sample(sent))
            sent += 1
            await asyncio.sleep(0.1)
        assert not link.connected
        settings = test_settings(database_url)
        restarted = LiveServer.__new__(LiveServer)
        LiveServer.__init__(restarted, settings)
        restarted.port, restarted.url = port, f"http://127.0.0.1:{port}"
        import uvicorn

        restarted.server = uvicorn.Server(
            uvicorn.Config(
                restarted.app,
                host="127.0.0.1",
                port=port,
                log_config=None,
                ws_max_size=1 << 20,
                lifespan="on",
            )
        )
        import threading

        restarted.thread = threading.Thread(target=restarted.server.run, daemon=True)
        settings.port = port
        restarted.start()
        try:
            await link.wait_connected(30)
            assert await link.flush(30)
            rows = await _count(restarted.url, tenant, asset["id"])
        finally:
            await asyncio.to_thread(restarted.stop)
    finally:
        await link.stop()
    alts = sorted(r["position.alt_rel_m"] for r in rows)
    assert len(rows) == sent == 30
    assert alts == sorted(float(i % 50) for i in range(30))


@pytest.mark.slow
async def test_a_30_second_link_cut_loses_nothing(live_server, tenant: Tenant, tmp_path):
    """10 Hz telemetry through a proxy cut for 30 s: every sample is stored exactly once."""
    from tests.netproxy import TcpProxy

    asset = tenant.create_asset("uav")
    cfg = _cfg(asset)
    proxy = await TcpProxy("127.0.0.1", live_server.port).start()
    link = Link(
        f"http://127.0.0.1:{proxy.port}",
        cfg.name,
        cfg.secret,
        tmp_path / "link.db",
        LinkSettings(backoff_min=0.1, backoff_max=1.0, traffic=Traffic(heartbeat_s=2.0)),
        seed=5,
    )
    await link.start()
    sent = 0
    try:
        await link.wait_connected(15)
        for _ in range(10):
            await link.send_telemetry(_sample(sent))
            sent += 1
            await asyncio.sleep(0.1)  # the 10 Hz rate itself
        proxy.cut()
        # 300 samples on a 10 Hz schedule (a late one is sent at once, not dropped): on a busy
        # machine the cut lasts a little over 30 s rather than carrying fewer samples
        cut_at = time.monotonic()
        for k in range(300):
            await link.send_telemetry(_sample(sent))
            sent += 1
            await asyncio.sleep(max(0.0, cut_at + (k + 1) * 0.1 - time.monotonic()))
        assert not link.connected
        proxy.restore()
        await link.wait_connected(30)
        assert await link.flush(30)
    finally:
        await link.stop()
        await proxy.stop()
    rows = await _count(live_server.url, tenant, asset["id"])
    assert len(rows) == sent == 310
    assert sorted(r["position.alt_rel_m"] for r in rows) == sorted(
        float(i % 50) for i in range(sent)
    )


async def test_a_flooding_asset_is_limited_and_others_keep_their_service(
    live_server, tenant: Tenant, tmp_path
):
    """One asset floods 10,000 messages/s: the excess is refused with an error and counted, the flooder's
    socket is closed (it must replay from its last ack: nothing it sent past a refusal is acked), and
    another asset's telemetry still reaches its operator."""
    flooder, quiet = tenant.create_asset("uav"), tenant.create_asset("uav")
    fcfg, qcfg = _cfg(flooder), _cfg(quiet)
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        token = (
            await c.post("/api/v1/assets/login", json={"name": fcfg.name, "secret": fcfg.secret})
        ).json()["access_token"]
    before = services_of(live_server.app).hub.counters.rate_limited
    link = Link(live_server.url, qcfg.name, qcfg.secret, tmp_path / "quiet.db", seed=6)
    await link.start()
    ws_url = live_server.url.replace("http", "ws")
    replies: list[dict] = []
    sent = 0
    try:
        await link.wait_connected(15)
        async with (
            websockets.connect(f"{ws_url}/ws/operator?token={tenant.tokens['viewer']}") as op,
            websockets.connect(
                f"{ws_url}/ws/asset", additional_headers={"Authorization": f"Bearer {token}"}
            ) as fl,
        ):
            await op.send(
                json.dumps(
                    {
                        "v": 1,
                        "type": "subscribe",
                        "id": "6f1c3a3e-58a4-4d1e-9f55-000000000009",
                        "seq": 0,
                        "ts": 0,
                        "payload": {"asset_ids": [quiet["id"]]},
                    }
                )
            )
            await fl.send(
                json.dumps(
                    {
                        "v": 1,
                        "type": "hello",
                        "id": "6f1c3a3e-58a4-4d1e-9f55-000000000010",
                        "seq": 0,
                        "ts": 0,
                        "payload": {
                            "stream": "6f1c3a3e-58a4-4d1e-9f55-0000000000bb",
                            "agent": "asset_agent",
                            "version": "t",
                        },
                    }
                )
            )
            assert json.loads(await fl.recv())["type"] == "welcome"

            async def drain() -> int:
                try:
                    async for raw in fl:
                        replies.append(json.loads(raw))
                except websockets.ConnectionClosed as closed:
                    return closed.rcvd.code if closed.rcvd else 0
                return fl.close_code or 0

            drainer = asyncio.create_task(drain())
            started = time.monotonic()
            with contextlib.suppress(websockets.ConnectionClosed):
                for seq in range(1, 10_001):
                    await fl.send(
                        json.dumps(
                            {
                                "v": 1,
                                "type": "event",
                                "id": str(uuid.uuid4()),
                                "seq": seq,
                                "ts": 0,
                                "payload": {"name": "flood", "message": ""},
                            }
                        )
                    )
                    sent = seq
                    if seq % 1000 == 0:
                        await asyncio.sleep(max(0.0, started + seq / 10_000 - time.monotonic()))
            code = await asyncio.wait_for(drainer, 15)
            # the quiet asset's telemetry still reaches its operator
            for i in range(20):
                await link.send_telemetry(_sample(i))
            received = 0
            while received < 20:
                msg = json.loads(await asyncio.wait_for(op.recv(), 10))
                if msg["type"] == "telemetry":
                    received += 1
            assert await link.flush(15)
    finally:
        await link.stop()
    assert code == 1008
    errors = [m for m in replies if m["type"] == "error"]
    assert errors and errors[0]["payload"]["code"] == "rate_limited"
    assert services_of(live_server.app).hub.counters.rate_limited - before >= 1
    acked = max((m["payload"]["seq"] for m in replies if m["type"] == "ack"), default=0)
    assert acked < sent  # nothing past the refusal is acknowledged: the client still holds it
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        stored = (
            await c.get(
                f"/api/v1/assets/{flooder['id']}/events",
                params={"limit": 10000, "start": "1970-01-01T00:00:00Z"},
                headers=tenant.h("viewer"),
            )
        ).json()
    assert len(stored) >= acked  # every acknowledged message is stored


async def test_sql_store_retention_prunes_old_samples(database_url):
    from datetime import UTC, datetime, timedelta

    from server.kit.db import make_engine, make_sessionmaker
    from server.telemetry.sql import SqlTelemetryStore
    from server.telemetry.store import Query, Sample

    engine = make_engine(database_url)
    store = SqlTelemetryStore(make_sessionmaker(engine), engine.dialect.name)
    import uuid as _uuid

    from sqlalchemy import insert

    from server.assets.models import Asset
    from server.organizations.models import Organization

    org_id, asset_id = _uuid.uuid4(), _uuid.uuid4()
    async with make_sessionmaker(engine)() as db:
        await db.execute(
            insert(Organization).values(
                id=org_id, name=f"ret-{org_id.hex[:8]}", created_at=datetime.now(UTC)
            )
        )
        now = datetime.now(UTC)
        await db.execute(
            insert(Asset).values(
                id=asset_id,
                organization_id=org_id,
                name=f"ret-{asset_id.hex[:8]}",
                kind="uav",
                description="",
                secret_hash="x",
                secret_rotated_at=now,
                attributes={},
                created_at=now,
                updated_at=now,
            )
        )
        await db.commit()
    now = datetime.now(UTC)
    await store.write(
        [
            Sample(asset_id, now - timedelta(days=10), 1, {"a": 1.0}),
            Sample(asset_id, now - timedelta(minutes=1), 2, {"a": 2.0}),
        ]
    )
    await store.write(
        [Sample(asset_id, now - timedelta(minutes=1), 2, {"a": 2.0})]
    )  # a replay: ignored
    # prune is global: other tests sharing this database may have stored old samples too
    assert await store.prune(now - timedelta(days=1)) >= 1
    rows = await store.query(Query(asset_id, now - timedelta(days=30), now))
    assert [r["a"] for r in rows] == [2.0]
    await engine.dispose()


async def test_force_login_closes_the_old_sessions_sockets_with_4001(live_server, tenant: Tenant):
    url = live_server.url.replace("http", "ws") + f"/ws/operator?token={tenant.tokens['operator']}"
    async with websockets.connect(url) as ws:
        await ws.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "subscribe",
                    "id": "6f1c3a3e-58a4-4d1e-9f55-000000000020",
                    "seq": 0,
                    "ts": 0,
                    "payload": {"asset_ids": []},
                }
            )
        )
        async with httpx.AsyncClient(base_url=live_server.url) as c:
            r = await c.post(
                "/api/v1/auth/login",
                json={
                    "email": tenant.emails["operator"],
                    "password": Tenant.PASSWORD,
                    "force": True,
                },
            )
            assert r.status_code == 200
        with pytest.raises(websockets.ConnectionClosed) as info:
            while True:
                await asyncio.wait_for(ws.recv(), 10)
    assert info.value.rcvd.code == 4001
