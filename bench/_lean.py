"""A lean WebSocket client for the load generator: 10,000 sends and 20,000 deliveries a second
must not need more cores than the server they measure.

Frames out are pre-encoded: a client must mask, and the mask key 0000 is a valid key whose XOR
leaves the payload as it is, so a frame is its header, four zero bytes and the text — no masking
pass, no random key (no system call) per send. Frames in (a server's, unmasked) are parsed in
`data_received` and each text message goes to `on_text` as bytes, without a task or a queue per
message. Pings are answered. It speaks only what the benchmark needs: the opening handshake,
text frames, ping/pong, close.
"""

from __future__ import annotations

import asyncio
import base64
import os
import struct
from collections.abc import Callable
from urllib.parse import urlsplit

_ZERO_MASK = b"\x00\x00\x00\x00"


def frame(text: str | bytes, opcode: int = 0x1) -> bytes:
    """A final client frame of `text`, masked with the zero key."""
    data = text.encode() if isinstance(text, str) else text
    n = len(data)
    if n < 126:
        head = bytes((0x80 | opcode, 0x80 | n))
    elif n < 1 << 16:
        head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
    else:
        head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
    return head + _ZERO_MASK + data


class LeanSocket(asyncio.Protocol):
    """One client WebSocket; `on_text(bytes)` hears every text message."""

    def __init__(self, on_text: Callable[[bytes], None]) -> None:
        self.on_text = on_text
        self.transport: asyncio.Transport | None = None
        self.handshake: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.close_code: int | None = None
        self._buf = b""
        self._open = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def data_received(self, data: bytes) -> None:
        buf = self._buf + data if self._buf else data
        if not self._open:
            head, sep, rest = buf.partition(b"\r\n\r\n")
            if not sep:
                self._buf = buf
                return
            self._open = True
            if not self.handshake.done():
                self.handshake.set_result(head)
            buf = rest
        pos, end = 0, len(buf)
        while end - pos >= 2:
            b0, n = buf[pos], buf[pos + 1] & 0x7F
            head = 2
            if n == 126:
                if end - pos < 4:
                    break
                n, head = (buf[pos + 2] << 8) | buf[pos + 3], 4
            elif n == 127:
                if end - pos < 10:
                    break
                (n,) = struct.unpack_from("!Q", buf, pos + 2)
                head = 10
            if end - pos < head + n:
                break
            payload = buf[pos + head : pos + head + n]
            pos += head + n
            opcode = b0 & 0x0F
            if opcode == 0x1:
                self.on_text(payload)
            elif opcode == 0x9:
                self.send(payload, opcode=0xA)
            elif opcode == 0x8:
                self.close_code = struct.unpack("!H", payload[:2])[0] if len(payload) >= 2 else 1005
                self.close()
        self._buf = buf[pos:]

    def send(self, text: str | bytes, opcode: int = 0x1) -> None:
        """Write a frame now (a closed socket drops it: its messages show up as lost)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(frame(text, opcode))

    def close(self, code: int = 1000) -> None:
        """Send a close frame and end the connection."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(frame(struct.pack("!H", code), opcode=0x8))
            self.transport.close()

    def connection_lost(self, exc: Exception | None) -> None:
        if self.close_code is None:
            self.close_code = 1006
        if not self.handshake.done():
            self.handshake.set_exception(ConnectionError("closed during the handshake"))
        if not self.closed.done():
            self.closed.set_result(None)


async def connect(
    url: str, path: str, on_text: Callable[[bytes], None], headers: dict[str, str] | None = None
) -> LeanSocket:
    """Open `path` on the server at `url` (http://host:port); returns once it answered 101."""
    parts = urlsplit(url)
    loop = asyncio.get_running_loop()
    _, sock = await loop.create_connection(
        lambda: LeanSocket(on_text), parts.hostname, parts.port or 80
    )
    key = base64.b64encode(os.urandom(16)).decode()
    extra = "".join(f"{k}: {v}\r\n" for k, v in (headers or {}).items())
    assert sock.transport is not None
    sock.transport.write(
        (
            f"GET {path} HTTP/1.1\r\nHost: {parts.netloc}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"{extra}\r\n"
        ).encode()
    )
    head = await asyncio.wait_for(sock.handshake, 60)
    status = head.split(b" ", 2)[1] if b" " in head else b"?"
    if status != b"101":
        sock.close()
        raise ConnectionError(f"WebSocket handshake answered {status.decode()}: {head[:200]!r}")
    return sock
