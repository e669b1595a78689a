"""An idle HTTP connection: the reverse proxy gives it up before the server does.

nginx keeps idle connections to the replicas (`keepalive 32` in deploy/nginx/aerobase.conf) and
picks one for the next request. Had a replica closed it first (uvicorn's own default: after 5 s),
a request nginx sent into that close would fail; nginx retries a GET on another replica, but a POST
(a run started, an abort) would come back 502."""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

import pytest

from server.config import Settings

NGINX_CONF = Path(__file__).resolve().parents[2] / "deploy" / "nginx" / "aerobase.conf"
UVICORN_DEFAULT_KEEP_ALIVE_S = 5  # uvicorn.Config's timeout_keep_alive when not given
SERVER_KEEP_ALIVE_S = Settings.model_fields["http_keep_alive_s"].default


def test_every_proxy_upstream_gives_up_an_idle_connection_before_the_server_does() -> None:
    upstreams = dict(re.findall(r"upstream\s+(\w+)\s*\{([^}]*)\}", NGINX_CONF.read_text()))
    assert set(upstreams) == {"aerobase_servers", "aerobase_video"}
    for name, body in upstreams.items():
        assert re.search(r"^\s*keepalive\s+\d+;", body, re.M), f"{name} keeps no idle connections"
        held = re.search(r"^\s*keepalive_timeout\s+(\d+)s;", body, re.M)
        assert held, f"{name} holds idle connections for nginx's unstated default (60 s)"
        assert int(held.group(1)) < SERVER_KEEP_ALIVE_S, name


async def _response(reader: asyncio.StreamReader) -> int:
    """One HTTP/1.1 response off the connection (its body read to its end); its status."""
    head = await reader.readuntil(b"\r\n\r\n")
    length = re.search(rb"(?im)^content-length:\s*(\d+)", head)
    assert length, head
    await reader.readexactly(int(length.group(1)))
    return int(head.split(b" ", 2)[1])


@pytest.mark.slow
async def test_an_idle_connection_is_still_served_after_uvicorns_own_keep_alive(
    live_server,
) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", live_server.port)
    try:
        writer.write(b"GET /api/health HTTP/1.1\r\nHost: aerobase\r\n\r\n")
        assert await _response(reader) == 200

        # idle past uvicorn's default: a close would end this read with b"" before the timeout
        closed: bytes | None = None
        try:
            async with asyncio.timeout(UVICORN_DEFAULT_KEEP_ALIVE_S + 1.5):
                closed = await reader.read(1)
        except TimeoutError:
            pass
        assert closed is None, f"the server closed an idle connection ({closed!r})"

        # a POST on the reused connection is answered (405: /api/health takes GET only)
        writer.write(b"POST /api/health HTTP/1.1\r\nHost: aerobase\r\nContent-Length: 0\r\n\r\n")
        assert await _response(reader) == 405
    finally:
        writer.close()
