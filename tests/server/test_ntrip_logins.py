"""Rovers logging in to the whole server's caster: many of one account at the same moment are
each answered (one check for the same credentials; the login limiter clears the account's
failures one success at a time), and failures count against the rover's address, the one its
proxy names, as failed user logins do."""

from __future__ import annotations

import asyncio
import base64

from server.deps import services_of
from tests.conftest import LiveServer, Tenant, test_settings
from tests.server.test_ntrip_caster import ask, basic, v1


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


async def test_failed_rover_logins_count_against_the_address_its_proxy_names(
    database_url, api, superuser_email
):
    # the tenant from the session's server: this one's strict limit is for the rovers
    tenant = Tenant(api, superuser_email, "rover-addresses")
    settings = test_settings(
        database_url, ntrip_port=0, ntrip_proxy_protocol=True,
        login_max_failures_address=3, login_max_failures_account=1000,
    )  # fmt: skip
    server = LiveServer(settings).start()
    try:
        caster = services_of(server.app).ntrip
        assert caster is not None

        async def rover(address: str, password: str) -> bytes:
            proxy_line = f"PROXY TCP4 {address} 127.0.0.1 40001 2101\r\n"
            return await ask(
                caster.port, proxy_line + v1("/", basic(tenant.emails["viewer"], password))
            )

        for i in range(3):  # three guesses (one repeated would not count again)
            assert (await rover("203.0.113.77", f"wrong-{i}")).startswith(b"HTTP/1.0 401")
        # that address is over its limit: even the right password is refused from it
        assert (await rover("203.0.113.77", Tenant.PASSWORD)).startswith(b"HTTP/1.0 401")
        # a rover at another address, on the same account, is not
        assert (await rover("198.51.100.77", Tenant.PASSWORD)).startswith(b"SOURCETABLE 200 OK")
    finally:
        await asyncio.to_thread(server.stop)
