"""Rovers of one account logging in to the whole server's caster at the same moment: each is
answered (the login limiter clears the account's failures one success at a time)."""

from __future__ import annotations

import asyncio
import base64

from server.deps import services_of
from tests.conftest import LiveServer, Tenant


async def test_many_rovers_of_one_account_logging_in_at_once_are_all_answered(
    live_server: LiveServer, api, superuser_email
):
    tenant = Tenant(api, superuser_email, "rovers")
    base = tenant.create_asset("landing_base")
    caster = services_of(live_server.app).ntrip
    assert caster is not None
    token = base64.b64encode(f"{tenant.emails['viewer']}:{Tenant.PASSWORD}".encode()).decode()
    request = f"GET / HTTP/1.0\r\nAuthorization: Basic {token}\r\n\r\n".encode()

    async def rover() -> bytes:
        reader, writer = await asyncio.open_connection("127.0.0.1", caster.port)
        try:
            writer.write(request)
            async with asyncio.timeout(30):
                return await reader.read()
        finally:
            writer.close()

    answers = await asyncio.gather(*(rover() for _ in range(40)))
    for answer in answers:
        assert answer.startswith(b"SOURCETABLE 200 OK\r\n"), answer[:200]
        assert f"STR;{base['name']};".encode() in answer
