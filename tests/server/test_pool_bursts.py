"""Bursts of requests that read through a second connection do not deadlock the requests' pool.

A request holds a connection of the requests' pool from its authentication on. Anything it then
reads through a session of its own must not come from that same pool: with every connection
held by a request waiting for a second one, nobody moves until the pool's timeout (30 s), and
every other request of the process waits with them. The telemetry reads have a pool of their
own; logins look up before the limiter takes its connection. A server with a requests' pool of
2 shows it with a handful of requests."""

from __future__ import annotations

import asyncio
import base64

import httpx

from assetlink.configfile import decrypt_config
from tests.conftest import LiveServer, Tenant, auth, login, test_settings

BURST = 12  # six times the pool


async def test_bursts_of_reads_and_wrong_credentials_on_a_pool_of_two(
    database_url, api, superuser_email
):
    tenant = Tenant(api, superuser_email, "pool-bursts")
    asset = tenant.create_asset("uav")
    settings = test_settings(database_url, db_pool_size=2, db_max_overflow=0)
    server = await asyncio.to_thread(LiveServer(settings).start)
    try:
        async with httpx.AsyncClient(base_url=server.url, timeout=90) as c:
            token = await asyncio.to_thread(
                login, httpx.Client(base_url=server.url), tenant.emails["viewer"], Tenant.PASSWORD,
                force=True,
            )  # fmt: skip
            reads = await asyncio.gather(
                *(
                    c.get(path, headers=auth(token))
                    for _ in range(BURST // 2)
                    for path in (
                        f"/api/v1/assets/{asset['id']}/telemetry",
                        f"/api/v1/assets/{asset['id']}/events",
                    )
                )
            )
            assert {r.status_code for r in reads} == {200}, [r.status_code for r in reads]
            guesses = await asyncio.gather(
                *(
                    c.post(
                        "/api/v1/assets/login",
                        json={"name": asset["name"], "secret": f"guess-{i}"},
                        headers={"X-Forwarded-For": f"198.18.2.{i + 1}"},
                    )
                    for i in range(BURST)
                )
            )
            codes = [r.status_code for r in guesses]
            assert set(codes) <= {401, 429}, codes
            logins = await asyncio.gather(
                *(
                    c.post(
                        "/api/v1/auth/login",
                        json={"email": tenant.emails["operator"], "password": f"guess-{i}"},
                        headers={"X-Forwarded-For": f"198.18.3.{i + 1}"},
                    )
                    for i in range(BURST)
                )
            )
            codes = [r.status_code for r in logins]
            assert set(codes) <= {401, 429}, codes
            change = {"current_password": "not-the-password", "new_password": "y" * 12}
            changes = await asyncio.gather(
                *(
                    c.post("/api/v1/auth/password", json=change, headers=auth(token))
                    for _ in range(BURST)
                )
            )
            codes = [r.status_code for r in changes]
            assert set(codes) <= {422, 429}, codes
            # and the right secret still gets in
            cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
            r = await c.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
            assert r.status_code == 200, r.text
    finally:
        await asyncio.to_thread(server.stop)
