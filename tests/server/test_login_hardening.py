"""Issue 14's login findings: disabling is per organisation, a disabled login says so, an admin
cannot disable themself, asset logins never lock out the right secret, the failed-login limit
holds under concurrency, and a config reissue rotates the secret only with its answer."""

from __future__ import annotations

import asyncio
import base64
import uuid

import httpx

from assetlink.configfile import decrypt_config
from server.kit.db import make_engine, make_sessionmaker
from server.kit.principal import Role
from server.organizations.repository import UserRepository
from server.organizations.service import add_member
from tests.conftest import Tenant, auth, login


async def _join(database_url: str, email: str, org_id: str, role: Role) -> None:
    """Make an existing user a member of another organisation (as `aerobase admin create-user`
    does for a known e-mail)."""
    engine = make_engine(database_url)
    try:
        async with make_sessionmaker(engine)() as db:
            user = await UserRepository(db).by_email(email)
            assert user is not None
            await add_member(db, uuid.UUID(org_id), user.id, role)
            await db.commit()
    finally:
        await engine.dispose()


def _login(api: httpx.Client, email: str, **extra: object) -> httpx.Response:
    body = {"email": email, "password": Tenant.PASSWORD, "force": True, **extra}
    return api.post("/api/v1/auth/login", json=body)


def test_disabling_a_user_in_one_organisation_leaves_their_other_organisation(
    api, superuser_email, database_url
):
    a, b = Tenant(api, superuser_email, "org-a"), Tenant(api, superuser_email, "org-b")
    email = a.emails["operator"]
    asyncio.run(_join(database_url, email, b.id, Role.viewer))
    r = api.patch(
        f"/api/v1/users/{a.user_ids['operator']}", json={"is_active": False}, headers=a.h()
    )
    assert r.status_code == 200 and r.json()["is_active"] is False
    # in org A: refused, and the answer says why (the password was right)
    r = _login(api, email, organization_id=a.id)
    assert r.status_code == 401 and r.json()["error"]["code"] == "account_disabled", r.text
    # in org B: a member as before
    r = _login(api, email, organization_id=b.id)
    assert r.status_code == 200, r.text
    me = api.get("/api/v1/auth/me", headers=auth(r.json()["access_token"])).json()
    assert me["organization_id"] == b.id and me["role"] == "viewer"
    # without naming one: the organisation where the user is still active
    r = _login(api, email)
    assert r.status_code == 200, r.text
    me = api.get("/api/v1/auth/me", headers=auth(r.json()["access_token"])).json()
    assert me["organization_id"] == b.id
    # B's admin still sees an active member; enabling again in A lets them back in there
    r = api.get(f"/api/v1/users/{a.user_ids['operator']}", headers=b.h())
    assert r.status_code == 200 and r.json()["is_active"] is True
    r = api.patch(
        f"/api/v1/users/{a.user_ids['operator']}", json={"is_active": True}, headers=a.h()
    )
    assert r.status_code == 200 and r.json()["is_active"] is True
    assert _login(api, email, organization_id=a.id).status_code == 200


def test_a_disabled_users_login_answers_account_disabled(api, tenant: Tenant):
    r = api.patch(
        f"/api/v1/users/{tenant.user_ids['viewer']}", json={"is_active": False}, headers=tenant.h()
    )
    assert r.status_code == 200
    r = _login(api, tenant.emails["viewer"])
    assert r.status_code == 401 and r.json()["error"]["code"] == "account_disabled", r.text
    # a wrong password still answers invalid_credentials: nothing is told without the password
    r = api.post(
        "/api/v1/auth/login",
        json={"email": tenant.emails["viewer"], "password": "not-the-password"},
    )
    assert r.status_code == 401 and r.json()["error"]["code"] == "invalid_credentials"


def test_an_admin_cannot_disable_themself(api, tenant: Tenant):
    r = api.patch(
        f"/api/v1/users/{tenant.user_ids['admin']}", json={"is_active": False}, headers=tenant.h()
    )
    assert r.status_code == 409, r.text
    assert r.json()["error"]["code"] == "self_disable"
    assert api.get("/api/v1/auth/me", headers=tenant.h()).status_code == 200


def test_wrong_asset_secrets_from_many_addresses_never_lock_out_the_right_one(api, tenant: Tenant):
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    codes = []
    for i in range(8):  # over the per-account limit (5), each from another address
        r = api.post(
            "/api/v1/assets/login",
            json={"name": cfg.name, "secret": "guess"},
            headers={"X-Forwarded-For": f"203.0.113.{i + 1}"},
        )
        codes.append(r.status_code)
    assert set(codes[:5]) == {401} and set(codes[5:]) == {429}, codes  # the wrong ones throttled
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert r.status_code == 200, r.text
    # and from an address that has only sent wrong secrets
    r = api.post(
        "/api/v1/assets/login",
        json={"name": cfg.name, "secret": cfg.secret, "force": True},
        headers={"X-Forwarded-For": "203.0.113.8"},
    )
    assert r.status_code == 200, r.text


async def test_30_concurrent_wrong_passwords_check_at_most_the_limit(live_server, tenant: Tenant):
    limit = live_server.settings.login_max_failures_account
    email = tenant.emails["viewer"]
    async with httpx.AsyncClient(base_url=live_server.url, timeout=60) as c:
        # 30 guesses, each another password (one repeated is not counted again: test_login_lockout)
        answers = await asyncio.gather(
            *(
                c.post("/api/v1/auth/login", json={"email": email, "password": f"wrong-{i:03d}"})
                for i in range(30)
            )
        )
        codes = [r.status_code for r in answers]
        checked = codes.count(401)
        assert set(codes) <= {401, 429}, codes
        # at most the limit, and no fewer: admissions queue per key, so the first `limit` go on
        assert checked == limit, f"{checked} wrong passwords checked (limit {limit}): {codes}"
        # the limit stands afterwards, for the right password too
        r = await c.post(
            "/api/v1/auth/login",
            json={"email": tenant.emails["viewer"], "password": Tenant.PASSWORD},
        )
    assert r.status_code == 429 and int(r.headers["Retry-After"]) > 0


def test_a_reissue_that_cannot_answer_rotates_nothing(api, tenant: Tenant):
    """The rotation and the answer are one unit of work: if the answer cannot be built, the old
    secret and session stand. (A name that is no Latin-1 could not go into the header.)"""
    for name in (f"基地-{uuid.uuid4().hex[:6]}", f"base\u2028{uuid.uuid4().hex[:6]}"):
        asset = tenant.create_asset("landing_base", name=name)
        cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
        token = api.post(
            "/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret}
        ).json()["access_token"]
        with httpx.Client(base_url=str(api.base_url), timeout=30) as own:  # its own connection
            r = own.post(
                f"/api/v1/assets/{asset['id']}/config",
                json={"password": "another-password-1"},
                headers=tenant.h(),
            )
        if r.status_code == 200:  # the answer was built: the new file holds the new secret
            new = decrypt_config(r.content, "another-password-1")
            assert new.secret != cfg.secret and new.name == name
            assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 401
            old = api.post("/api/v1/assets/login", json={"name": name, "secret": cfg.secret})
            assert old.status_code == 401
        else:  # nothing was delivered, so nothing rotated
            assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 200, r.text
            again = api.post(
                "/api/v1/assets/login",
                json={"name": name, "secret": cfg.secret, "force": True},
            )
            assert again.status_code == 200, (r.status_code, again.text)


def test_a_user_logs_in_after_the_concurrent_burst_clears(api, tenant: Tenant):
    """A successful login clears the account's failures (the limiter's rows are taken back)."""
    email = tenant.emails["operator"]
    for i in range(3):  # distinct guesses: the same wrong password again is not counted
        api.post("/api/v1/auth/login", json={"email": email, "password": f"nope-nope-{i}"})
    token = login(api, email, Tenant.PASSWORD, force=True)
    assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 200
    for i in range(4):  # four more failures after the success: still under the limit of 5
        r = api.post("/api/v1/auth/login", json={"email": email, "password": f"nope-again-{i}"})
        assert r.status_code == 401
