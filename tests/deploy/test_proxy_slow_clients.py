"""The deployment's proxy closes clients that never finish their request head.

nginx runs deploy/nginx/aerobase.conf (the file docker-compose.yml mounts) in front of an
`aerobase server`: 60 trickling HTTP heads, 60 trickling WebSocket upgrades and 20 silent
connections to the proxy are each closed within 15 s (client_header_timeout 10s; nginx's own
default, 60 s, would hold them all).
"""

from __future__ import annotations

from urllib.parse import urlsplit

import httpx
import pytest

from tests.replicas import proxy, replicas
from tests.server.test_slow_clients import HELD_AT_MOST_S, slow_clients

pytestmark = pytest.mark.slow


async def test_the_proxy_closes_trickling_and_silent_clients_within_15_s(database_url, tmp_path):
    with replicas(database_url, tmp_path, count=1) as servers:
        with proxy([servers[0][0]], tmp_path) as url:
            times = await slow_clients(urlsplit(url).port or 80)
            async with httpx.AsyncClient(base_url=url) as c:
                assert (await c.get("/api/health")).status_code == 200
    for kind, seconds in times.items():
        late = [round(s, 1) for s in seconds if s > HELD_AT_MOST_S]
        assert not late, f"{len(late)} of {len(seconds)} {kind} connections held over 15 s"
