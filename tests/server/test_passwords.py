"""Passwords change: a user changes their own (the current one checked as a login checks it), an
administrator resets a member's (every session of theirs ends), and neither gives an
organisation's admin an account that opens more than their organisation."""

from __future__ import annotations

import asyncio
import base64

import httpx

from assetlink.configfile import decrypt_config
from server.kit.principal import Role
from tests.conftest import SUPERUSER_PASSWORD, Tenant, auth, login
from tests.server.test_login_hardening import _join

NEW = "a-brand-new-password-1"


def _change(api: httpx.Client, token: str, current: str, new: str = NEW) -> httpx.Response:
    body = {"current_password": current, "new_password": new}
    return api.post("/api/v1/auth/password", json=body, headers=auth(token))


def _logs_in(api: httpx.Client, email: str, password: str) -> int:
    body = {"email": email, "password": password, "force": True}
    return api.post("/api/v1/auth/login", json=body).status_code


def test_a_user_changes_their_password_and_keeps_their_session(api, tenant: Tenant):
    email, token = tenant.emails["operator"], tenant.tokens["operator"]
    assert _change(api, token, Tenant.PASSWORD).status_code == 204
    assert (
        api.get("/api/v1/auth/me", headers=auth(token)).status_code == 200
    )  # the caller's goes on
    assert _logs_in(api, email, Tenant.PASSWORD) == 401
    assert _logs_in(api, email, NEW) == 200
    rows = api.get("/api/v1/audit", headers=tenant.h(), params={"action": "user.password_changed"})
    assert rows.status_code == 200 and any(e["target"] == email for e in rows.json()), rows.text


def test_a_password_change_refuses_a_wrong_current_one_as_a_login_would(api, tenant: Tenant):
    token = tenant.tokens["viewer"]
    r = _change(api, token, Tenant.PASSWORD, Tenant.PASSWORD)
    assert r.status_code == 422 and r.json()["error"]["code"] == "same_password", r.text
    r = _change(api, token, Tenant.PASSWORD, "short")
    assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error", r.text
    codes = [_change(api, token, f"guess-{i:03d}").status_code for i in range(6)]
    # a stolen session cannot guess the password: the account's failed-login limit applies
    assert codes == [422] * 5 + [429], codes
    r = _change(api, token, f"guess-{0:03d}")
    assert r.status_code == 422 and r.json()["error"]["code"] == "wrong_password"  # a repeat
    assert _change(api, token, Tenant.PASSWORD).status_code == 429  # the right one: still limited


def test_an_asset_has_no_password_to_change(api, tenant: Tenant):
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    token = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    r = _change(api, token.json()["access_token"], cfg.secret)
    assert r.status_code == 403 and r.json()["error"]["code"] == "not_a_user", r.text


def test_an_admin_resets_a_members_password_and_their_sessions_end(api, tenant: Tenant):
    email, token = tenant.emails["viewer"], tenant.tokens["viewer"]
    r = api.post(
        f"/api/v1/users/{tenant.user_ids['viewer']}/password",
        json={"new_password": NEW},
        headers=tenant.h(),
    )
    assert r.status_code == 204, r.text
    r = api.get("/api/v1/auth/me", headers=auth(token))
    assert r.status_code == 401 and r.json()["error"]["code"] == "session_ended"
    assert "reset by an administrator" in r.json()["error"]["message"]
    assert _logs_in(api, email, Tenant.PASSWORD) == 401
    assert _logs_in(api, email, NEW) == 200


def test_an_operator_cannot_reset_and_an_admin_not_their_own(api, tenant: Tenant):
    path = f"/api/v1/users/{tenant.user_ids['viewer']}/password"
    r = api.post(path, json={"new_password": NEW}, headers=tenant.h("operator"))
    assert r.status_code == 403, r.text
    r = api.post(
        f"/api/v1/users/{tenant.user_ids['admin']}/password",
        json={"new_password": NEW},
        headers=tenant.h(),
    )
    assert r.status_code == 409 and r.json()["error"]["code"] == "self_reset", r.text
    assert _logs_in(api, tenant.emails["admin"], Tenant.PASSWORD) == 200  # nothing changed


def test_only_a_superuser_resets_a_member_of_other_organisations(
    api, superuser_email, database_url
):
    a, b = Tenant(api, superuser_email, "pw-a"), Tenant(api, superuser_email, "pw-b")
    email = a.emails["operator"]
    asyncio.run(_join(database_url, email, b.id, Role.viewer))
    path = f"/api/v1/users/{a.user_ids['operator']}/password"
    r = api.post(path, json={"new_password": NEW}, headers=a.h())
    assert r.status_code == 403 and r.json()["error"]["code"] == "other_organisations", r.text
    assert _logs_in(api, email, Tenant.PASSWORD) == 200  # nothing changed
    root = login(api, superuser_email, SUPERUSER_PASSWORD, force=True, organization_id=a.id)
    assert api.post(path, json={"new_password": NEW}, headers=auth(root)).status_code == 204
    assert _logs_in(api, email, NEW) == 200
