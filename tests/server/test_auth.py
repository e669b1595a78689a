"""Login, one live session per account, take-over, logout, renewal, rate limits, audit."""

import uuid

from tests.conftest import Tenant, auth, login


def test_login_returns_opaque_bearer_token(api, tenant: Tenant):
    r = api.post(
        "/api/v1/auth/login",
        json={"email": tenant.emails["viewer"], "password": Tenant.PASSWORD, "force": True},
    )
    assert r.status_code == 200
    body = r.json()
    assert body["token_type"] == "bearer"
    assert len(body["access_token"]) >= 43  # 256 bits, base64url
    assert api.get("/api/v1/auth/me", headers=auth(body["access_token"])).json()["role"] == "viewer"


def test_second_login_is_refused_while_first_session_lives(api, tenant: Tenant):
    r = api.post(
        "/api/v1/auth/login", json={"email": tenant.emails["operator"], "password": Tenant.PASSWORD}
    )
    assert r.status_code == 409
    err = r.json()["error"]
    assert err["code"] == "session_active"
    assert "live session" in err["message"] and "force" in err["message"]
    # the first session still works
    assert api.get("/api/v1/auth/me", headers=tenant.h("operator")).status_code == 200


def test_force_ends_the_first_session_and_is_audited(api, tenant: Tenant):
    old = tenant.tokens["operator"]
    new = login(api, tenant.emails["operator"], Tenant.PASSWORD, force=True)
    r = api.get("/api/v1/auth/me", headers=auth(old))
    assert r.status_code == 401
    assert r.json()["error"]["code"] == "session_ended"
    assert "took this session over" in r.json()["error"]["message"]
    assert api.get("/api/v1/auth/me", headers=auth(new)).status_code == 200
    events = api.get(
        "/api/v1/audit", params={"action": "session.taken_over"}, headers=tenant.h("admin")
    ).json()
    assert any(e["actor_id"] == tenant.user_ids["operator"] for e in events)


def test_logout_ends_the_session_and_allows_a_new_login(api, tenant: Tenant):
    assert api.post("/api/v1/auth/logout", headers=tenant.h("viewer")).status_code == 204
    assert api.get("/api/v1/auth/me", headers=tenant.h("viewer")).status_code == 401
    login(api, tenant.emails["viewer"], Tenant.PASSWORD)


def test_renew_rotates_the_token(api, tenant: Tenant):
    r = api.post("/api/v1/auth/renew", headers=tenant.h("viewer"))
    assert r.status_code == 200
    new = r.json()["access_token"]
    assert new != tenant.tokens["viewer"]
    assert api.get("/api/v1/auth/me", headers=tenant.h("viewer")).status_code == 401
    assert api.get("/api/v1/auth/me", headers=auth(new)).status_code == 200


def test_wrong_password_is_401_without_saying_which_part_was_wrong(api, tenant: Tenant):
    for email in (tenant.emails["viewer"], f"nobody-{uuid.uuid4().hex}@x.test"):
        r = api.post("/api/v1/auth/login", json={"email": email, "password": "wrong-password-xx"})
        assert r.status_code == 401
        assert r.json()["error"]["message"] == "wrong e-mail or password"


def test_failed_logins_are_rate_limited_per_account(api, tenant: Tenant):
    email = tenant.emails["viewer"]
    codes = [
        api.post(
            "/api/v1/auth/login",
            json={"email": email, "password": "nope-nope-nope"},
            headers={"X-Forwarded-For": f"10.9.{i}.1"},
        ).status_code
        for i in range(5)
    ]
    assert codes == [401] * 5
    r = api.post(
        "/api/v1/auth/login",
        json={"email": email, "password": Tenant.PASSWORD, "force": True},
        headers={"X-Forwarded-For": "10.9.99.1"},
    )
    assert r.status_code == 429
    assert int(r.headers["Retry-After"]) > 0
    assert r.json()["error"]["code"] == "rate_limited"


def test_failed_logins_are_rate_limited_per_address(database_url, superuser_email):
    """A separate server whose per-address limit is low; every account differs, one address."""
    import httpx

    from tests.conftest import LiveServer, test_settings

    server = LiveServer(test_settings(database_url, login_max_failures_address=3)).start()
    try:
        with httpx.Client(base_url=server.url) as api:
            octet = uuid.uuid4().int % 250
            addr = {"X-Forwarded-For": f"10.77.{octet}.1"}
            for i in range(3):
                r = api.post(
                    "/api/v1/auth/login",
                    json={"email": f"u{i}-{uuid.uuid4().hex}@x.test", "password": "whatever-xx"},
                    headers=addr,
                )
                assert r.status_code == 401
            r = api.post(
                "/api/v1/auth/login",
                json={"email": superuser_email, "password": "x" * 12},
                headers=addr,
            )
            assert r.status_code == 429 and "address" in r.json()["error"]["message"]
            other = api.post(
                "/api/v1/auth/login",
                json={"email": f"z-{uuid.uuid4().hex}@x.test", "password": "whatever-xx"},
                headers={"X-Forwarded-For": f"10.78.{octet}.2"},
            )
            assert other.status_code == 401
    finally:
        server.stop()


def test_password_is_stored_as_argon2id(database_url, tenant: Tenant):
    import asyncio

    from sqlalchemy import select

    from server.kit.db import make_engine, make_sessionmaker
    from server.organizations.models import User

    async def fetch() -> str:
        engine = make_engine(database_url)
        async with make_sessionmaker(engine)() as db:
            user = (
                await db.execute(select(User).where(User.email == tenant.emails["admin"]))
            ).scalar_one()
        await engine.dispose()
        return user.password_hash

    stored = asyncio.run(fetch())
    assert stored.startswith("$argon2id$")
    assert Tenant.PASSWORD not in stored


def test_idle_session_expires(database_url, superuser_email):
    """Session validity follows the idle timeout (a server with a 10 s idle limit; time moved by SQL)."""
    import asyncio
    from datetime import timedelta

    import httpx
    from sqlalchemy import update

    from server.auth.models import AuthSession
    from server.kit.db import make_engine, make_sessionmaker
    from tests.conftest import SUPERUSER_PASSWORD, LiveServer, test_settings

    server = LiveServer(test_settings(database_url, session_idle_s=10)).start()
    try:
        with httpx.Client(base_url=server.url) as api:
            r = api.post(
                "/api/v1/auth/login",
                json={"email": superuser_email, "password": SUPERUSER_PASSWORD, "force": True},
            )
            token, sid = r.json()["access_token"], r.json()["session_id"]
            assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 200

            async def age() -> None:
                engine = make_engine(database_url)
                async with make_sessionmaker(engine)() as db:
                    s = await db.get(AuthSession, uuid.UUID(sid))
                    await db.execute(
                        update(AuthSession)
                        .where(AuthSession.id == s.id)
                        .values(last_seen_at=s.last_seen_at - timedelta(seconds=11))
                    )
                    await db.commit()
                await engine.dispose()

            asyncio.run(age())
            r = api.get("/api/v1/auth/me", headers=auth(token))
            assert r.status_code == 401 and r.json()["error"]["code"] == "session_expired"
            # an expired session does not block a new login
            login(api, superuser_email, SUPERUSER_PASSWORD)
    finally:
        server.stop()
