"""Assets: registration with an encrypted config file, name uniqueness, rotation, asset login."""

import base64
import uuid

from assetlink.configfile import BadFormat, WrongPassword, decrypt_config
from tests.conftest import Tenant, auth


def test_registration_returns_a_decryptable_config_file(api, tenant: Tenant, live_server):
    asset = tenant.create_asset("landing_base", password="base-password-123")
    data = base64.b64decode(asset["config_file"])
    assert data[:4] == b"ABCF" and data[4] == 1
    cfg = decrypt_config(data, "base-password-123")
    assert cfg.asset_id == asset["id"] and cfg.name == asset["name"] and cfg.kind == "landing_base"
    assert cfg.server_url == live_server.url
    assert len(cfg.secret) >= 43
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert r.status_code == 200
    me = api.get("/api/v1/auth/me", headers=auth(r.json()["access_token"])).json()
    assert me["kind"] == "asset" and me["id"] == asset["id"]


def test_wrong_password_and_tampering_are_detected(tenant: Tenant):
    data = base64.b64decode(tenant.create_asset(password="right-password-1")["config_file"])
    try:
        decrypt_config(data, "wrong-password-1")
        raise AssertionError("decrypted with a wrong password")
    except WrongPassword:
        pass
    tampered = bytearray(data)
    tampered[-20] ^= 1
    try:
        decrypt_config(bytes(tampered), "right-password-1")
        raise AssertionError("decrypted a tampered file")
    except WrongPassword:
        pass
    try:
        decrypt_config(b"PK\x03\x04junk", "right-password-1")
        raise AssertionError("accepted a foreign file")
    except BadFormat:
        pass


def test_server_keeps_only_a_hash_of_the_secret(database_url, tenant: Tenant):
    import asyncio

    from server.assets.models import Asset
    from server.kit.db import make_engine, make_sessionmaker

    asset = tenant.create_asset(password="p" * 12)
    secret = decrypt_config(base64.b64decode(asset["config_file"]), "p" * 12).secret

    async def fetch() -> Asset:
        engine = make_engine(database_url)
        async with make_sessionmaker(engine)() as db:
            row = await db.get(Asset, uuid.UUID(asset["id"]))
        await engine.dispose()
        return row

    row = asyncio.run(fetch())
    assert secret not in row.secret_hash and "p" * 12 not in str(row.__dict__)


def test_name_is_globally_unique(api, tenant: Tenant, superuser_email):
    other = Tenant(api, superuser_email, "other")
    name = tenant.create_asset()["name"]
    r = api.post(
        "/api/v1/assets",
        json={"name": name, "kind": "uav", "password": "x" * 12},
        headers=other.h("admin"),
    )
    assert r.status_code == 409 and r.json()["error"]["code"] == "name_taken"


def test_password_must_have_twelve_characters(api, tenant: Tenant):
    r = api.post(
        "/api/v1/assets",
        json={"name": "short-pw", "kind": "uav", "password": "x" * 11},
        headers=tenant.h("admin"),
    )
    assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error"


def test_reissue_rotates_the_secret_and_ends_sessions(api, tenant: Tenant):
    asset = tenant.create_asset(password="first-password-1")
    old = decrypt_config(base64.b64decode(asset["config_file"]), "first-password-1")
    token = api.post("/api/v1/assets/login", json={"name": old.name, "secret": old.secret}).json()[
        "access_token"
    ]
    r = api.post(
        f"/api/v1/assets/{asset['id']}/config",
        json={"password": "second-password-2"},
        headers=tenant.h("admin"),
    )
    assert r.status_code == 200 and r.headers["content-type"] == "application/octet-stream"
    new = decrypt_config(r.content, "second-password-2")
    assert new.secret != old.secret
    assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 401
    assert (
        api.post("/api/v1/assets/login", json={"name": old.name, "secret": old.secret}).status_code
        == 401
    )
    assert (
        api.post("/api/v1/assets/login", json={"name": new.name, "secret": new.secret}).status_code
        == 200
    )


def test_asset_login_follows_the_one_session_rule(api, tenant: Tenant):
    asset = tenant.create_asset(password="p" * 12)
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "p" * 12)
    assert (
        api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret}).status_code
        == 200
    )
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert r.status_code == 409 and r.json()["error"]["code"] == "session_active"
    assert (
        api.post(
            "/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret, "force": True}
        ).status_code
        == 200
    )


def test_uav_binds_to_a_base_of_its_own_organisation(api, tenant: Tenant, superuser_email):
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    assert uav["base_id"] == base["id"]
    other = Tenant(api, superuser_email, "other")
    r = api.post(
        "/api/v1/assets",
        json={
            "name": f"u-{uuid.uuid4().hex[:8]}",
            "kind": "uav",
            "password": "x" * 12,
            "base_id": base["id"],
        },
        headers=other.h("admin"),
    )
    assert r.status_code == 404


def test_crud(api, tenant: Tenant):
    asset = tenant.create_asset("uav", description="first")
    listed = api.get("/api/v1/assets", headers=tenant.h("viewer")).json()
    assert [a["id"] for a in listed] == [asset["id"]]
    assert "config_file" not in listed[0] and "secret_hash" not in listed[0]
    r = api.patch(
        f"/api/v1/assets/{asset['id']}", json={"description": "second"}, headers=tenant.h("admin")
    )
    assert r.status_code == 200 and r.json()["description"] == "second"
    assert api.delete(f"/api/v1/assets/{asset['id']}", headers=tenant.h("admin")).status_code == 204
    assert api.get(f"/api/v1/assets/{asset['id']}", headers=tenant.h("admin")).status_code == 404
