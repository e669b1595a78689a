"""A client cannot choose its address through the deployment's proxy.

nginx runs deploy/nginx/aerobase.conf (the file docker-compose.yml mounts) in front of an
`aerobase server` that believes X-Forwarded-For from the proxy's address alone
(AEROBASE_FORWARDED_ALLOW_IPS, as the compose file sets it). The client connects from another
loopback address than the proxy's, and forges X-Forwarded-For and X-Real-IP on every request:
the audit log records its real address, and the failed-login limit per address holds at 20.
"""

from __future__ import annotations

import random

import httpx
import pytest

from tests.conftest import Tenant
from tests.replicas import proxy, replicas

pytestmark = pytest.mark.slow

ADDRESS_LIMIT = 20


def _forged(i: int) -> dict[str, str]:
    return {"X-Forwarded-For": f"203.0.113.{i % 250 + 1}", "X-Real-IP": f"198.51.100.{i % 250 + 1}"}


def test_a_forged_x_forwarded_for_through_the_proxy_changes_nothing(
    database_url, api, superuser_email, tmp_path
):
    tenant = Tenant(api, superuser_email, "trust")
    # the client's real address: loopback, but not the proxy's 127.0.0.1, and new to the
    # limiter on every run (a database kept between runs holds earlier runs' failures)
    client = f"127.{random.randint(1, 254)}.{random.randint(0, 255)}.{random.randint(2, 254)}"
    settings = {
        "AEROBASE_LOGIN_MAX_FAILURES_ADDRESS": str(ADDRESS_LIMIT),
        "AEROBASE_FORWARDED_ALLOW_IPS": "127.0.0.1",  # nginx connects from here
    }
    with replicas(database_url, tmp_path, count=1, settings=settings) as servers:
        with proxy([servers[0][0]], tmp_path) as url:
            transport = httpx.HTTPTransport(local_address=client)
            with httpx.Client(base_url=url, transport=transport, timeout=30) as c:
                # a login, forged headers and all: the audit log has the real address
                r = c.post(
                    "/api/v1/auth/login",
                    json={
                        "email": tenant.emails["viewer"],
                        "password": Tenant.PASSWORD,
                        "force": True,
                    },
                    headers=_forged(0),
                )
                assert r.status_code == 200, r.text
                logins = api.get(
                    "/api/v1/audit", params={"action": "login"}, headers=tenant.h("admin")
                ).json()
                viewer = tenant.user_ids["viewer"]
                addrs = [e["client_addr"] for e in logins if e["actor_id"] == viewer]

                # 30 wrong passwords, each "from" another forged address: the first 20 are
                # checked, the rest refused under the limit of the one real address
                codes = [
                    c.post(
                        "/api/v1/auth/login",
                        json={"email": f"nobody-{i}@{tenant.name}.test", "password": "wrong-1"},
                        headers=_forged(i + 1),
                    ).status_code
                    for i in range(30)
                ]
    assert addrs[0] == client, addrs  # the newest first
    assert codes == [401] * ADDRESS_LIMIT + [429] * (30 - ADDRESS_LIMIT), codes
