"""Hostile input on the sockets (issue 14, items 2, 10, 11): out-of-range and non-finite values,
binary frames, too many sockets, subscriptions or messages, silent and slow peers."""

from __future__ import annotations

import asyncio
import json
import socket
import time
import uuid
from collections.abc import Iterator

import httpx
import pytest
import websockets

from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import eventually
from tests.server.realtime_client import (
    asset_socket,
    asset_token,
    close_code,
    message,
    next_of,
    uav_sample,
    ws_url,
)


@pytest.fixture(scope="module")
def tight(database_url: str) -> Iterator[LiveServer]:
    """A server with small socket limits, so each is reached in a few messages."""
    settings = test_settings(
        database_url,
        ws_handshake_s=0.5,
        ws_send_timeout_s=1.0,
        ws_max_sockets_per_session=2,
        ws_max_subscriptions=2,
        ws_operator_rate_per_s=2.0,
        ws_operator_burst=4.0,
    )
    server = LiveServer(settings).start()
    yield server
    server.stop()


def subscribe(*ids: str) -> str:
    return message("subscribe", {"asset_ids": list(ids)})


# --- item 2: values out of range are refused at the edge, and never fail another asset ---------


async def test_out_of_range_seq_and_ts_are_refused_and_another_asset_keeps_its_service(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """ts = 1e17 ms and seq = 2^63 once failed the shared storage batch: the other asset's socket
    was closed with 1011. Now the offender is answered invalid_envelope (its socket stays open)
    and every message of the other asset is acked and stored."""
    bad_uav, good_uav = tenant.create_asset("uav"), tenant.create_asset("uav")
    bad_token, good_token = (
        asset_token(live_server.url, bad_uav),
        asset_token(live_server.url, good_uav),
    )
    bad_rows = [
        message("telemetry", uav_sample(), seq=1, ts=10**17),
        message("telemetry", uav_sample(), seq=2**63),
        message("event", {"name": "x"}, seq=2**63 - 1),
        message("telemetry", uav_sample(), seq=3, ts=-1),
    ]
    async with (
        asset_socket(live_server.url, bad_token) as bad,
        asset_socket(live_server.url, good_token) as good,
    ):
        for round_ in range(5):  # the bad rows and the good ones reach the same batches
            for i, row in enumerate(bad_rows):
                await bad.send(row)
                await good.send(
                    message("telemetry", uav_sample(round_ * 4 + i), seq=round_ * 4 + i + 1)
                )
        errors = [await next_of(bad, "error") for _ in range(5 * len(bad_rows))]
        last = 0
        while last < 20:
            last = (await next_of(good, "ack"))["payload"]["seq"]
        # the offender's socket is still served: a good message of its own is acked
        await bad.send(message("telemetry", uav_sample(), seq=4))
        assert (await next_of(bad, "ack"))["payload"]["seq"] == 4
    assert {e["payload"]["code"] for e in errors} == {"invalid_envelope"}
    assert any("ts" in e["payload"]["message"] for e in errors)
    assert any("seq" in e["payload"]["message"] for e in errors)
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        rows = (
            await c.get(
                f"/api/v1/assets/{good_uav['id']}/telemetry",
                params={"start": "2000-01-01T00:00:00Z", "end": "2100-01-01T00:00:00Z"},
                headers=tenant.h("viewer"),
            )
        ).json()
    assert len(rows) == 20


async def test_an_unstorable_row_fails_alone_in_its_batch(database_url: str) -> None:
    """Rows that pass no edge (written straight to the ingest): the one the database cannot hold
    fails with RowRejected, every other row of the same batch is stored (SQLite and PostgreSQL)."""
    from datetime import UTC, datetime

    from sqlalchemy import insert

    from server.assets.models import Asset
    from server.kit.db import make_engine, make_sessionmaker
    from server.organizations.models import Organization
    from server.realtime.ingest import Ingest, Item, RowRejected
    from server.telemetry.sql import SqlTelemetryStore
    from server.telemetry.store import Query

    engine = make_engine(database_url)
    sessions = make_sessionmaker(engine)
    org, good, bad = uuid.uuid4(), uuid.uuid4(), uuid.uuid4()
    now = datetime.now(UTC)
    async with sessions() as db:
        await db.execute(
            insert(Organization).values(id=org, name=f"iso-{org.hex[:8]}", created_at=now)
        )
        for asset in (good, bad):
            await db.execute(
                insert(Asset).values(
                    id=asset, organization_id=org, name=f"iso-{asset.hex[:8]}", kind="uav",
                    description="", secret_hash="x", secret_rotated_at=now, attributes={},
                    created_at=now, updated_at=now,
                )
            )  # fmt: skip
        await db.commit()
    store = SqlTelemetryStore(sessions, engine.dialect.name)
    ingest = Ingest(sessions, store, max_delay_s=0.2)
    ingest.start()
    ts = int(time.time() * 1000)
    try:
        good_stream, bad_stream = uuid.uuid4(), uuid.uuid4()
        for stream, asset in ((good_stream, good), (bad_stream, bad)):
            await ingest.last_seq(stream, asset)
        items = [
            Item(good_stream, good, org, i, "telemetry", ts + i, {"n": i}) for i in range(1, 11)
        ]
        items.insert(5, Item(bad_stream, bad, org, 2**63, "telemetry", ts, {"n": -1}))
        futures = [ingest.submit(item) for item in items]
        outcomes = await asyncio.wait_for(asyncio.gather(*futures, return_exceptions=True), 30)
    finally:
        await ingest.stop()
    assert [type(o) for o in outcomes] == [type(None)] * 5 + [RowRejected] + [type(None)] * 5
    start = datetime.fromtimestamp(ts / 1000 - 60, UTC)
    end = datetime.fromtimestamp(ts / 1000 + 60, UTC)
    rows = await store.query(Query(good, start, end))
    assert sorted(r["n"] for r in rows) == list(range(1, 11))
    await engine.dispose()


# --- item 10: non-finite numbers ------------------------------------------------------------


async def test_nan_in_uav_telemetry_is_dropped_with_an_error_and_an_event(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """NaN attitude over the raw socket was acked and silently not stored. Now the asset is told
    (invalid_payload naming the field), the rest of the sample is stored, and the asset's events
    record telemetry_field_dropped."""
    uav = tenant.create_asset("uav")
    token = asset_token(live_server.url, uav)
    sample = uav_sample(
        attitude={"roll_deg": float("nan"), "pitch_deg": 1.0, "yaw_deg": 2.0},
        battery={"percent": 80.0, "voltage_v": float("inf")},
    )
    async with asset_socket(live_server.url, token) as ws:
        text = message("telemetry", sample, seq=1)
        assert "NaN" in text and "Infinity" in text
        await ws.send(text)
        error = await next_of(ws, "error")
        assert (await next_of(ws, "ack"))["payload"]["seq"] == 1
    assert error["payload"]["code"] == "invalid_payload" and error["payload"]["re_seq"] == 1
    assert "payload.attitude.roll_deg" in error["payload"]["message"]
    assert "payload.battery.voltage_v" in error["payload"]["message"]
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as c:
        latest = (await c.get(f"/api/v1/assets/{uav['id']}/telemetry/latest")).json()
        events = (
            await c.get(
                f"/api/v1/assets/{uav['id']}/events", params={"start": "2000-01-01T00:00:00Z"}
            )
        ).json()
    assert latest["position.lat"] == 41.0 and latest["battery.percent"] == 80.0
    assert "battery.voltage_v" not in latest and not any(k.startswith("attitude") for k in latest)
    dropped = [e for e in events if e["name"] == "telemetry_field_dropped"]
    assert len(dropped) == 1 and dropped[0]["severity"] == "warning"
    assert dropped[0]["data"]["fields"] == ["attitude.roll_deg", "battery.voltage_v"]


async def test_nan_reaches_no_operator_and_the_drop_event_does(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """Operators get the kept sample (valid JSON, no NaN) and the telemetry_field_dropped event."""
    uav = tenant.create_asset("uav")
    token = asset_token(live_server.url, uav)
    async with websockets.connect(
        ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"])
    ) as op:
        await op.send(subscribe(uav["id"]))
        async with asset_socket(live_server.url, token) as ws:
            await ws.send(message("telemetry", uav_sample(heading_deg=float("-inf")), seq=1))
            await next_of(ws, "ack")
        got = [json.loads(await asyncio.wait_for(op.recv(), 10)) for _ in range(2)]
    kinds = {m["type"]: m for m in got}
    assert (
        "heading_deg" not in kinds["telemetry"]["payload"]
        or kinds["telemetry"]["payload"]["heading_deg"] is None
    )
    assert kinds["event"]["payload"]["name"] == "telemetry_field_dropped"


# --- item 11: frames, sockets, subscriptions, rates, time ----------------------------------


async def test_a_binary_frame_closes_either_socket_with_1003(
    live_server: LiveServer, tenant: Tenant
) -> None:
    uav = tenant.create_asset("uav")
    async with asset_socket(live_server.url, asset_token(live_server.url, uav)) as ws:
        await ws.send(b'{"v": 1}')
        assert await close_code(ws) == 1003
    async with websockets.connect(
        ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"])
    ) as op:
        await op.send(subscribe())
        await op.send(b"\x00\x01")
        assert await close_code(op) == 1003
    # a binary hello, too
    async with websockets.connect(
        ws_url(live_server.url, "/ws/asset", asset_token(live_server.url, uav))
    ) as ws:
        await ws.send(b"hello")
        assert await close_code(ws) == 1003


async def test_sockets_per_session_are_bounded_with_4429(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """200 of 200 sockets once opened on one viewer token; the default bound is 8."""
    limit = getattr(live_server.settings, "ws_max_sockets_per_session", 8)
    url = ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"])
    sockets = [await websockets.connect(url) for _ in range(limit)]
    try:
        for ws in sockets:  # each of them is served
            await ws.send(subscribe(str(uuid.uuid4())))
            assert (await next_of(ws, "error"))["payload"]["code"] == "not_found"
        async with websockets.connect(url) as extra:
            assert await close_code(extra) == 4429
        await sockets[0].close()

        # a closed socket frees its slot
        async def reopened() -> bool:
            async with websockets.connect(url) as again:
                await again.send(subscribe())
                try:
                    await asyncio.wait_for(again.recv(), 0.3)
                except TimeoutError:
                    return True
                except websockets.ConnectionClosed:
                    return False
                return True

        await eventually(reopened, 10, "a freed slot")
    finally:
        for ws in sockets:
            await ws.close()


async def test_unknown_ids_are_answered_once_per_message_and_bounded(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """20,000 unknown ids from 5 sockets once cost one query and one error frame per id (and
    raised other clients' latency 12.7 -> 95 ms): now one query and one error per message, and at
    most 5000 ids in a message."""
    url = ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"])
    async with websockets.connect(url) as op:
        await op.send(subscribe(*(str(uuid.uuid4()) for _ in range(1000))))
        error = await next_of(op, "error")
        assert (
            error["payload"]["code"] == "not_found"
            and "and 980 more" in error["payload"]["message"]
        )
        await op.send(subscribe(*(str(uuid.uuid4()) for _ in range(5001))))
        assert (await next_of(op, "error"))["payload"]["code"] == "invalid_payload"
        with pytest.raises(TimeoutError):  # one error per message, not one per id
            await asyncio.wait_for(op.recv(), 0.5)


async def test_subscriptions_per_socket_are_bounded(
    tight: LiveServer, superuser_email: str
) -> None:
    tenant = Tenant(httpx.Client(base_url=tight.url, timeout=30), superuser_email)
    ids = [tenant.create_asset("uav")["id"] for _ in range(3)]
    async with websockets.connect(ws_url(tight.url, "/ws/operator", tenant.tokens["viewer"])) as op:
        await op.send(subscribe(*ids))
        error = await next_of(op, "error")
        assert error["payload"]["code"] == "too_many_subscriptions"
        assert "1 not followed" in error["payload"]["message"]


async def test_an_operator_flooding_messages_is_closed_with_4429(
    tight: LiveServer, superuser_email: str
) -> None:
    tenant = Tenant(httpx.Client(base_url=tight.url, timeout=30), superuser_email)
    async with websockets.connect(ws_url(tight.url, "/ws/operator", tenant.tokens["viewer"])) as op:
        for _ in range(20):
            try:
                await op.send(subscribe(str(uuid.uuid4())))
            except websockets.ConnectionClosed:
                break
        replies = []
        with pytest.raises(websockets.ConnectionClosed) as closed:
            while True:
                replies.append(json.loads(await asyncio.wait_for(op.recv(), 10)))
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 4429
    assert replies[-1]["payload"]["code"] == "rate_limited"


async def test_silent_sockets_are_closed_after_the_handshake_time(
    tight: LiveServer, superuser_email: str
) -> None:
    """Sockets that said nothing were held for 40 s; now 4408 after ws_handshake_s (0.5 s here)."""
    tenant = Tenant(httpx.Client(base_url=tight.url, timeout=30), superuser_email)
    uav = tenant.create_asset("uav")
    started = time.monotonic()
    async with (
        websockets.connect(ws_url(tight.url, "/ws/operator", tenant.tokens["viewer"])) as op,
        websockets.connect(ws_url(tight.url, "/ws/asset", asset_token(tight.url, uav))) as asset,
    ):
        assert await close_code(op) == 4408
        assert await close_code(asset) == 4408
    assert time.monotonic() - started < 5


@pytest.mark.slow  # 20 MB through the fan-out, about 4 s
async def test_a_reader_that_stalls_is_closed_after_the_send_timeout(
    tight: LiveServer, superuser_email: str
) -> None:
    """An operator that stops reading once held its socket, its queue and its subscriptions; now the
    server closes it when a frame has waited ws_send_timeout_s (1 s here)."""
    from server.deps import services_of

    closers = services_of(tight.app).hub.closers
    tenant = Tenant(httpx.Client(base_url=tight.url, timeout=30), superuser_email)
    uav = tenant.create_asset("uav")
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect(("127.0.0.1", tight.port))
    stalled.setblocking(False)
    before = set(closers)
    op = await websockets.connect(
        ws_url(tight.url, "/ws/operator", tenant.tokens["viewer"]),
        sock=stalled,
        max_queue=1,
        max_size=None,
    )
    try:
        await op.send(subscribe(uav["id"]))
        session = (await eventually(lambda: set(closers) - before, 10, "the operator socket")).pop()
        big = "x" * 500_000
        async with asset_socket(tight.url, asset_token(tight.url, uav)) as ws:
            for seq in range(1, 41):  # 20 MB towards a reader that takes none of it
                await ws.send(message("event", {"name": "bulk", "message": big}, seq=seq))
            started = time.monotonic()
            await eventually(lambda: session not in closers, 15, "the stalled socket closed")
        assert time.monotonic() - started < 10
    finally:
        op.transport.abort()


async def test_nul_characters_are_stored_or_refused_never_fail_the_batch(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """A NUL character is valid JSON but PostgreSQL's text cannot hold it: the event is stored
    without it, and the telemetry sample (JSON column) keeps it escaped."""
    uav = tenant.create_asset("uav")
    async with asset_socket(live_server.url, asset_token(live_server.url, uav)) as ws:
        await ws.send(
            message("event", {"name": "a\x00b", "message": "c\x00d", "data": {"e": "f\x00"}}, seq=1)
        )
        await ws.send(message("telemetry", uav_sample(flight_mode="AU\x00TO"), seq=2))
        replies = []
        while not any(r["type"] == "ack" and r["payload"]["seq"] == 2 for r in replies):
            replies.append(await next_of(ws, "ack", "error"))
    assert [r for r in replies if r["type"] == "error"] == []
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as c:
        events = (
            await c.get(
                f"/api/v1/assets/{uav['id']}/events", params={"start": "2000-01-01T00:00:00Z"}
            )
        ).json()
        latest = (await c.get(f"/api/v1/assets/{uav['id']}/telemetry/latest")).json()
    assert [(e["name"], e["message"]) for e in events] == [("ab", "cd")]
    assert latest["flight_mode"] in ("AU\x00TO", "AUTO")


@pytest.mark.slow  # its own server
async def test_a_peer_that_answers_no_ping_is_dropped(
    database_url: str, superuser_email: str
) -> None:
    """A socket whose peer went silent (no pong) was held 40 s (uvicorn's 20 s + 20 s); the server's
    own options now take AEROBASE_WS_PING_INTERVAL_S / _TIMEOUT_S (0.3 s each here)."""
    import threading

    import uvicorn

    from server.cli import uvicorn_options

    settings = test_settings(database_url, ws_ping_interval_s=0.3, ws_ping_timeout_s=0.3)
    live = LiveServer(settings)
    live.server = uvicorn.Server(
        uvicorn.Config(live.app, lifespan="on", **uvicorn_options(settings))
    )
    live.thread = threading.Thread(target=live.server.run, daemon=True)
    live.start()
    try:
        tenant = Tenant(httpx.Client(base_url=live.url, timeout=30), superuser_email)
        raw = socket.create_connection(("127.0.0.1", live.port))
        raw.sendall(
            (
                f"GET /ws/operator?token={tenant.tokens['viewer']} HTTP/1.1\r\n"
                f"Host: 127.0.0.1:{live.port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        raw.settimeout(10)
        assert raw.recv(4096).startswith(b"HTTP/1.1 101")
        started = time.monotonic()
        # it subscribes, then reads nothing and answers no ping: the server gives up on it
        frame = subscribe().encode()
        mask = b"\x00\x00\x00\x00"
        raw.sendall(bytes([0x81, 0x80 | 126]) + len(frame).to_bytes(2, "big") + mask + frame)

        def closed() -> bool:
            try:
                while raw.recv(65536):
                    pass  # pings and nothing else; never answered
                return True
            except ConnectionResetError:
                return True
            except TimeoutError:
                return False

        assert await asyncio.to_thread(closed)
        assert time.monotonic() - started < 5
        raw.close()
    finally:
        live.stop()
