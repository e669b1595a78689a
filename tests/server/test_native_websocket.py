"""The hot sockets served natively (server/realtime/native.py, rfc6455.py): RFC 6455 as a peer sees
it over a real TCP connection, byte by byte where it matters, and the same routes under
uvicorn's own WebSocket implementation (asgi_socket.py)."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import struct
import threading
import uuid
from collections.abc import Iterator

import pytest
import uvicorn
import websockets

from server.realtime import rfc6455 as ws
from server.realtime.native_socket import CLOSE_TIMEOUT_S
from tests.conftest import LiveServer, Tenant, test_settings
from tests.server.realtime_client import (
    asset_socket,
    asset_token,
    message,
    next_of,
    uav_sample,
    ws_url,
)

KEY = base64.b64encode(b"0123456789abcdef").decode()


def client_frame(opcode: int, payload: bytes, fin: bool = True, rsv: int = 0) -> bytes:
    """A masked client frame."""
    mask = os.urandom(4)
    n = len(payload)
    head = bytes([(0x80 if fin else 0) | rsv | opcode])
    if n < 126:
        head += bytes([0x80 | n])
    elif n < 1 << 16:
        head += bytes([0x80 | 126]) + struct.pack("!H", n)
    else:
        head += bytes([0x80 | 127]) + struct.pack("!Q", n)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return head + mask + masked


class Peer:
    """A raw TCP WebSocket client that reads the server's frames itself."""

    def __init__(self, port: int, path: str, headers: str = "") -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.sock.sendall(
            (
                f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\n{headers}\r\n"
            ).encode()
        )
        self.buf = b""
        head = self._until(b"\r\n\r\n")
        self.status = int(head.split(b" ", 2)[1])
        self.head = head.decode("latin-1")

    def _until(self, marker: bytes) -> bytes:
        while marker not in self.buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        head, _, self.buf = self.buf.partition(marker)
        return head

    def _exact(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def frame(self) -> tuple[int, bytes]:
        """The next frame from the server (unmasked, final)."""
        b0, b1 = self._exact(2)
        assert b1 & 0x80 == 0, "server frames are never masked"
        n = b1 & 0x7F
        if n == 126:
            (n,) = struct.unpack("!H", self._exact(2))
        elif n == 127:
            (n,) = struct.unpack("!Q", self._exact(8))
        return b0 & 0x0F, self._exact(n)

    def next_data(self) -> dict:
        """The next text message (skipping the server's pings)."""
        while True:
            opcode, payload = self.frame()
            if opcode == ws.TEXT:
                return json.loads(payload)
            assert opcode == ws.PING, (opcode, payload)

    def close_code(self) -> int:
        """Read until the server's close frame; its code."""
        while True:
            opcode, payload = self.frame()
            if opcode == ws.CLOSE:
                return ws.parse_close(payload)[0]

    def closed_tcp(self) -> bool:
        """The server closed the TCP connection (after its close frame)."""
        try:
            return self.sock.recv(1) == b""
        except ConnectionResetError:
            return True

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)


def operator(live: LiveServer, tenant: Tenant) -> Peer:
    """An operator socket of the viewer, past the handshake."""
    peer = Peer(
        live.port,
        f"/ws/operator?token={tenant.tokens['viewer']}",
        f"Sec-WebSocket-Key: {KEY}\r\nSec-WebSocket-Version: 13\r\n",
    )
    assert peer.status == 101
    assert f"sec-websocket-accept: {ws.accept_key(KEY)}".lower() in peer.head.lower()
    return peer


def subscribe(*ids: str) -> bytes:
    """A subscribe message's text."""
    return json.dumps({"type": "subscribe", "payload": {"asset_ids": list(ids)}}).encode()


def test_fragments_with_a_ping_between_them_make_one_message(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """A subscribe split into three frames, a ping in the middle: the ping is answered at once
    (same payload), the message is handled whole; fed one byte at a time."""
    peer = operator(live_server, tenant)
    unknown = str(uuid.uuid4())
    text = subscribe(unknown)
    data = (
        client_frame(ws.TEXT, text[:10], fin=False)
        + client_frame(ws.PING, b"are you there")
        + client_frame(ws.CONTINUATION, text[10:20], fin=False)
        + client_frame(ws.CONTINUATION, text[20:])
    )
    for i in range(len(data)):
        peer.send(data[i : i + 1])
    assert peer.frame() == (ws.PONG, b"are you there")
    error = peer.next_data()
    assert error["type"] == "error" and error["payload"]["code"] == "not_found"
    assert unknown in error["payload"]["message"]


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (client_frame(ws.TEXT, b"\xff\xfe not utf-8"), 1007),
        (client_frame(ws.BINARY, b"\x00\x01"), 1003),
        (client_frame(0x3, b"reserved"), 1002),
        (client_frame(ws.TEXT, b"{}", rsv=0x40), 1002),  # no extension negotiated
        (client_frame(ws.PING, b"x", fin=False), 1002),  # a fragmented control frame
        (client_frame(ws.CONTINUATION, b"x"), 1002),  # continuing nothing
        (bytes([0x81, 0x02]) + b"{}", 1002),  # unmasked
        (bytes([0x81, 0xFF]) + struct.pack("!Q", (1 << 20) + 1) + os.urandom(4), 1009),
    ],
    ids=["utf8", "binary", "opcode", "rsv", "fragmented-ping", "continuation", "unmasked", "size"],
)
def test_protocol_errors_close_with_the_code_rfc_6455_names(
    live_server: LiveServer, tenant: Tenant, frame: bytes, code: int
) -> None:
    peer = operator(live_server, tenant)
    peer.send(client_frame(ws.TEXT, subscribe()))
    peer.send(frame)
    assert peer.close_code() == code
    # failing the connection (RFC 6455 §7.1.7), the server closes TCP without waiting for our
    # close frame, which would take CLOSE_TIMEOUT_S: a read that outlasts half of it fails
    peer.sock.settimeout(CLOSE_TIMEOUT_S / 2)
    assert peer.closed_tcp()


def test_the_closing_handshake_is_answered_and_the_server_closes_tcp(
    live_server: LiveServer, tenant: Tenant
) -> None:
    peer = operator(live_server, tenant)
    peer.send(client_frame(ws.TEXT, subscribe()))
    peer.send(client_frame(ws.CLOSE, struct.pack("!H", 1000) + b"bye"))
    assert peer.close_code() == 1000
    assert peer.closed_tcp()


@pytest.mark.parametrize(
    "headers",
    ["Sec-WebSocket-Version: 13\r\n", f"Sec-WebSocket-Key: {KEY}\r\nSec-WebSocket-Version: 8\r\n"],
    ids=["no-key", "version-8"],
)
def test_a_bad_handshake_is_refused_with_400(
    live_server: LiveServer, tenant: Tenant, headers: str
) -> None:
    peer = Peer(live_server.port, f"/ws/operator?token={tenant.tokens['viewer']}", headers)
    assert peer.status == 400
    assert peer.closed_tcp()


def test_other_websocket_paths_are_left_to_uvicorn(live_server: LiveServer) -> None:
    """No other WebSocket route exists: uvicorn's own implementation refuses it (Starlette's
    403 before accept), as it would without the native path."""
    peer = Peer(
        live_server.port,
        "/ws/nothing-here",
        f"Sec-WebSocket-Key: {KEY}\r\nSec-WebSocket-Version: 13\r\n",
    )
    assert peer.status == 403


def test_frame_reader_reassembles_across_any_split() -> None:
    """Pure: three messages (one fragmented, one 70 kB with a 64-bit length) and a ping, fed in
    chunks of every size from 1 to 17 bytes, come out the same."""
    big = b"x" * 70_000
    stream = (
        client_frame(ws.TEXT, b"hello")
        + client_frame(ws.TEXT, b"frag", fin=False)
        + client_frame(ws.PING, b"p")
        + client_frame(ws.CONTINUATION, b"mented")
        + client_frame(ws.BINARY, big)
    )
    expected = [(ws.TEXT, b"hello"), (ws.PING, b"p"), (ws.TEXT, b"fragmented"), (ws.BINARY, big)]
    for size in range(1, 18):
        reader = ws.FrameReader(1 << 20)
        got = []
        for i in range(0, len(stream), size):
            got += reader.feed(stream[i : i + size])
        assert got == expected, size
    # the shortcut for one whole text frame agrees with feed, and declines everything else
    for text in (b"", b"x" * 125, b"y" * 126, b"z" * 1000):
        whole = client_frame(ws.TEXT, text)
        assert ws.FrameReader(1 << 20).single_text(whole) == text
        assert ws.FrameReader(1 << 20).feed(whole) == [(ws.TEXT, text)]
        assert ws.FrameReader(1 << 20).single_text(whole[:-1] if text else whole[:5]) is None
    for other in (
        client_frame(ws.TEXT, b"ab", fin=False),
        client_frame(ws.BINARY, b"ab"),
        client_frame(ws.PING, b"ab"),
        bytes([0x81, 0x02]) + b"ab",  # unmasked
        client_frame(ws.TEXT, b"ab") + client_frame(ws.TEXT, b"cd"),  # two frames
        client_frame(ws.TEXT, b"w" * 2000),  # over this reader's size
    ):
        assert ws.FrameReader(1000).single_text(other) is None
    assert ws.frame(ws.TEXT, big)[:10] == bytes([0x81, 127]) + struct.pack("!Q", 70_000)
    assert ws.frame(ws.TEXT, b"y" * 1000)[:4] == bytes([0x81, 126]) + struct.pack("!H", 1000)
    assert ws.frame(ws.PONG, b"p") == bytes([0x8A, 1]) + b"p"
    assert ws.close_frame(1000, "é" * 100)[2:4] == struct.pack("!H", 1000)
    assert len(ws.close_frame(1000, "é" * 100)) <= 127  # a control frame's limit, cut cleanly


@pytest.fixture
def uvicorn_own(database_url: str) -> Iterator[LiveServer]:
    """The app under uvicorn's own WebSocket implementation (no native path)."""
    from server.cli import uvicorn_options

    settings = test_settings(database_url)
    live = LiveServer(settings)
    options = {**uvicorn_options(settings), "ws": "websockets-sansio"}
    options.update(host="127.0.0.1", port=live.port)
    live.server = uvicorn.Server(uvicorn.Config(live.app, lifespan="on", **options))
    live.thread = threading.Thread(target=live.server.run, daemon=True)
    live.start()
    yield live
    live.stop()


@pytest.mark.slow  # its own server
async def test_the_sockets_work_under_any_asgi_server(
    uvicorn_own: LiveServer, tenant: Tenant
) -> None:
    """Under uvicorn's implementation (asgi_socket.py): telemetry acked and delivered, a binary
    frame closed with 1003 — the same contract."""
    uav = tenant.create_asset("uav")
    url = uvicorn_own.url
    async with websockets.connect(ws_url(url, "/ws/operator", tenant.tokens["viewer"])) as op:
        await op.send(json.dumps({"type": "subscribe", "payload": {"asset_ids": [uav["id"]]}}))
        async with asset_socket(url, asset_token(url, uav)) as asset:
            await asset.send(message("telemetry", uav_sample(1), seq=1))
            assert (await next_of(asset, "ack"))["payload"]["seq"] == 1
            got = await next_of(op, "telemetry")
            assert got["payload"]["asset_id"] == uav["id"]
            await asset.send(b"\x00")
            with pytest.raises(websockets.ConnectionClosed) as closed:
                await asyncio.wait_for(asset.recv(), 10)
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1003
