"""With its database out of reach, the server says so: `503 unavailable` with `Retry-After` on
every route that needs it (the REST API and the HTTP port's NTRIP routes), never `500
internal_error`; once the database is back, the same calls answer as before."""

from __future__ import annotations

import asyncio
import base64

import httpx
import pytest
from sqlalchemy.engine import make_url

from assetlink.auth import ServerUnavailable, SessionClient
from assetlink.configfile import decrypt_config
from tests.conftest import OWN_DATABASE_ROOT, LiveServer, Tenant, auth, login, test_settings
from tests.netproxy import TcpProxy
from tests.polling import eventually


async def test_the_database_out_of_reach_is_503_with_retry_after_then_back(own_database):
    # PostgreSQL whatever the suite runs on (SQLite, make test's default, has no link to cut)
    url = make_url(own_database)
    link = await TcpProxy(url.host or "127.0.0.1", url.port or 5432).start()
    proxied = url.set(host="127.0.0.1", port=link.port).render_as_string(hide_password=False)
    # started from a thread, and called from threads: the proxy to PostgreSQL runs in this
    # test's event loop
    server = await asyncio.to_thread(LiveServer(test_settings(proxied)).start)
    api = httpx.Client(base_url=server.url, timeout=60)
    try:
        tenant = await asyncio.to_thread(Tenant, api, OWN_DATABASE_ROOT, "db-away")
        asset = await asyncio.to_thread(tenant.create_asset, "landing_base")
        creds = base64.b64encode(f"{tenant.emails['viewer']}:{Tenant.PASSWORD}".encode()).decode()
        cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
        async with httpx.AsyncClient(base_url=server.url, timeout=60) as c:
            token = await asyncio.to_thread(
                login, api, tenant.emails["operator"], Tenant.PASSWORD, force=True
            )
            calls = [
                ("GET", "/api/v1/auth/me", auth(token), None),
                ("GET", "/api/v1/assets", auth(token), None),
                ("POST", "/api/v1/auth/login", {}, {"email": tenant.emails["viewer"],
                                                    "password": Tenant.PASSWORD, "force": True}),
                ("GET", "/ntrip/", {"Authorization": f"Basic {creds}"}, None),
            ]  # fmt: skip
            for method, path, headers, body in calls:
                r = await c.request(method, path, headers=headers, json=body)
                assert r.status_code == 200, (path, r.text)
            link.cut()
            for method, path, headers, body in calls:
                r = await c.request(method, path, headers=headers, json=body)
                assert r.status_code == 503, (path, r.status_code, r.text)
                assert r.json()["error"]["code"] == "unavailable", (path, r.text)
                assert int(r.headers["Retry-After"]) > 0, path
            # a daemon's login is told how long to wait (its link then waits at least that long)
            with pytest.raises(ServerUnavailable) as refused:
                await SessionClient(server.url, cfg.name, cfg.secret, c).login()
            assert refused.value.retry_after == 5
            link.restore()

            async def back() -> bool:
                return (await c.get("/api/v1/auth/me", headers=auth(token))).status_code == 200

            await eventually(back, 30, "the API answering with the database back")
            for method, path, headers, body in calls:
                r = await c.request(method, path, headers=headers, json=body)
                assert r.status_code == 200, (path, r.text)
    finally:
        await asyncio.to_thread(api.close)
        await asyncio.to_thread(server.stop)
        await link.stop()
