"""Limits of the sockets (issue 14, item 11): binary frames, too many sockets, subscriptions or
messages, silent and slow peers. Values (items 2 and 10) are in test_realtime_values.py."""

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


@pytest.mark.slow  # two server processes
async def test_sockets_per_session_are_bounded_across_replicas(
    database_url: str,
    api: httpx.Client,
    superuser_email: str,
    tmp_path,
    monkeypatch,  # type: ignore[no-untyped-def]
) -> None:
    """The slots live in the broker (Redis): a session's sockets on two replicas count together."""
    from tests.replicas import replicas

    monkeypatch.setenv("AEROBASE_WS_MAX_SOCKETS_PER_SESSION", "2")
    tenant = Tenant(api, superuser_email)
    with replicas(database_url, tmp_path) as started:
        a, b = (f"http://127.0.0.1:{port}" for port, _ in started)
        token = tenant.tokens["viewer"]
        on_a = await websockets.connect(ws_url(a, "/ws/operator", token))
        on_b = await websockets.connect(ws_url(b, "/ws/operator", token))
        try:
            for ws in (on_a, on_b):
                await ws.send(subscribe(str(uuid.uuid4())))
                assert (await next_of(ws, "error"))["payload"]["code"] == "not_found"
            for url in (a, b):
                async with websockets.connect(ws_url(url, "/ws/operator", token)) as extra:
                    assert await close_code(extra) == 4429
            await on_a.close()

            async def admitted_on_b() -> bool:
                async with websockets.connect(ws_url(b, "/ws/operator", token)) as again:
                    await again.send(subscribe(str(uuid.uuid4())))
                    try:
                        return bool((await next_of(again, "error", within=2))["payload"])
                    except websockets.ConnectionClosed:
                        return False

            await eventually(admitted_on_b, 15, "the slot freed on A taken on B")
        finally:
            await on_a.close()
            await on_b.close()


@pytest.mark.slow  # 6 MB through the fan-out
async def test_frames_held_back_by_a_slow_reader_arrive_complete_and_in_order(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """Frames go straight to the socket while it takes them; once the peer's window is full the
    transport pauses and they wait in the socket's queue (native.py). When the reader catches up
    (well within the send timeout) every frame arrives, once and in order."""
    from server.deps import services_of

    closers = services_of(live_server.app).hub.closers
    uav = tenant.create_asset("uav")
    slow = socket.socket()
    slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    slow.connect(("127.0.0.1", live_server.port))
    slow.setblocking(False)
    before = set(closers)
    op = await websockets.connect(
        ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"]),
        sock=slow,
        max_queue=1,
        max_size=None,
    )
    try:
        await op.send(subscribe(uav["id"]))
        session = (await eventually(lambda: set(closers) - before, 10, "the operator socket")).pop()
        sock = closers[session][0][0].__self__  # type: ignore[attr-defined]
        big = "y" * 200_000
        async with asset_socket(live_server.url, asset_token(live_server.url, uav)) as ws:
            for seq in range(1, 31):
                await ws.send(message("event", {"name": "bulk", "message": big}, seq=seq))
            # the reader has taken (almost) nothing: frames now wait in the server's socket
            await eventually(lambda: sock.paused and sock.waiting > 0, 10, "back-pressure")
            seqs = []
            while len(seqs) < 30:
                got = await next_of(op, "event", within=10)
                seqs.append(got["seq"])
        assert seqs == list(range(1, 31))
        assert session in closers  # not closed as a slow reader: it caught up in time
    finally:
        op.transport.abort()
