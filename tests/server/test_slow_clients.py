"""Clients that never finish their request head hold no connection past the head limit.

A live `aerobase server` (its own process, over real sockets on loopback) meets 60 connections
trickling an HTTP request head a byte a second, 60 trickling a WebSocket upgrade to /ws/asset
and 20 that send nothing: each is closed within 15 s (the limit is AEROBASE_HTTP_HEADER_TIMEOUT_S,
10 s by default), while an ordinary request is answered meanwhile and afterwards, and a
keep-alive connection idle between two requests for longer than the limit is still served.
"""

from __future__ import annotations

import asyncio
import re
import time

import httpx
import pytest

from tests.replicas import replicas

pytestmark = pytest.mark.slow

HELD_AT_MOST_S = 15.0
HTTP_HEAD = b"GET /api/health HTTP/1.1\r\nHost: aerobase\r\nX-Slow: "
UPGRADE_HEAD = (
    b"GET /ws/asset HTTP/1.1\r\nHost: aerobase\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    b"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: "
)


async def held_for(port: int, head: bytes | None, deadline_s: float) -> float:
    """Open a connection, send `head` and then one more byte a second (None: send nothing);
    the seconds until the server closed it, or `deadline_s` + 1 if it was still open then."""
    start = time.monotonic()
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        if head is not None:
            writer.write(head)
        while time.monotonic() - start < deadline_s:
            try:
                async with asyncio.timeout(1.0):
                    # a 408, or b"" at the close; whatever came, the close follows
                    if not await reader.read(4096):
                        return time.monotonic() - start
            except TimeoutError:
                if head is not None:
                    writer.write(b"a")
            except ConnectionError:
                return time.monotonic() - start
        return deadline_s + 1
    finally:
        writer.close()


async def _status(reader: asyncio.StreamReader) -> int:
    """One response off the connection (its body read); its status."""
    head = await reader.readuntil(b"\r\n\r\n")
    length = re.search(rb"(?im)^content-length:\s*(\d+)", head)
    await reader.readexactly(int(length.group(1)) if length else 0)
    return int(head.split(b" ", 2)[1])


async def slow_clients(port: int, deadline_s: float = HELD_AT_MOST_S) -> dict[str, list[float]]:
    """60 trickling HTTP heads, 60 trickling upgrades, 20 silent connections at once: how long
    each was held, by kind."""
    kinds = {"http": HTTP_HEAD, "upgrade": UPGRADE_HEAD, "silent": None}
    counts = {"http": 60, "upgrade": 60, "silent": 20}
    tasks = {
        kind: [asyncio.create_task(held_for(port, head, deadline_s)) for _ in range(counts[kind])]
        for kind, head in kinds.items()
    }
    return {kind: list(await asyncio.gather(*ts)) for kind, ts in tasks.items()}


async def test_trickling_and_silent_connections_are_closed_within_15_s(database_url, tmp_path):
    with replicas(database_url, tmp_path, count=1) as servers:
        port = servers[0][0]
        # a keep-alive connection that has had its answer (as the proxy's upstream ones): the
        # head limit does not apply while it idles between requests, only uvicorn's keep-alive
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /api/health HTTP/1.1\r\nHost: aerobase\r\n\r\n")
        assert await _status(reader) == 200
        held = asyncio.create_task(slow_clients(port))
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as c:
            started = time.monotonic()
            assert (await c.get("/api/health")).status_code == 200
            assert time.monotonic() - started < 1.0
            times = await held
            assert (await c.get("/api/health")).status_code == 200
        # idle longer than the head limit, still served
        writer.write(b"POST /api/health HTTP/1.1\r\nHost: aerobase\r\nContent-Length: 0\r\n\r\n")
        assert await _status(reader) == 405
        writer.close()
    for kind, seconds in times.items():
        late = [round(s, 1) for s in seconds if s > HELD_AT_MOST_S]
        assert not late, f"{len(late)} of {len(seconds)} {kind} connections held over 15 s"
