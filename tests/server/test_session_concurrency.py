"""Issue 48 finding 1: one live session per account holds under concurrency on every database.

Forced asset logins sent at once over real HTTP leave exactly one live session, and a credential
rotation racing them leaves none opened with the old secret; logins without force let one in.
Run on SQLite (the default) and on PostgreSQL (DATABASE_URL); the database's own partial unique
index is checked too, and the migration that made it."""

from __future__ import annotations

import asyncio
import base64
import tempfile
import uuid
from collections.abc import AsyncIterator
from datetime import UTC, datetime, timedelta

import httpx
import pytest
import sqlalchemy as sa
from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import create_async_engine

from assetlink.configfile import decrypt_config
from server import migrate
from server.auth.models import AuthSession
from server.kit.db import UTCDateTime, make_engine, make_sessionmaker
from server.kit.time import utcnow
from tests.conftest import PG_URL_DEFAULT, LiveServer, Tenant, auth

LOGINS = 20


def _credentials(asset: dict[str, object]) -> tuple[str, str]:
    cfg = decrypt_config(base64.b64decode(str(asset["config_file"])), "asset-password-123")
    return cfg.name, cfg.secret


async def _live(c: httpx.AsyncClient, tokens: list[str]) -> list[str]:
    """The tokens whose session still answers /auth/me."""
    answers = await asyncio.gather(*(c.get("/api/v1/auth/me", headers=auth(t)) for t in tokens))
    return [t for t, r in zip(tokens, answers, strict=True) if r.status_code == 200]


async def test_concurrent_forced_asset_logins_leave_one_live_session(
    live_server: LiveServer, tenant: Tenant
):
    asset = tenant.create_asset("uav")
    name, secret = _credentials(asset)
    body = {"name": name, "secret": secret, "force": True}
    async with httpx.AsyncClient(base_url=live_server.url, timeout=60) as c:
        before = await c.get(f"/api/v1/assets/{asset['id']}", headers=tenant.h("admin"))
        answers = await asyncio.gather(
            *(c.post("/api/v1/assets/login", json=body) for _ in range(LOGINS))
        )
        # a forced login takes the live session over: every one of them is let in, in turn
        assert [r.status_code for r in answers] == [200] * LOGINS, [r.text for r in answers]
        tokens = [r.json()["access_token"] for r in answers]
        live = await _live(c, tokens)
        assert len(live) == 1, f"{len(live)} of {LOGINS} concurrent forced logins left live"
        # logging in edits nothing of the asset: the same version (ETag) and time of change
        after = await c.get(f"/api/v1/assets/{asset['id']}", headers=tenant.h("admin"))
        assert after.json()["updated_at"] == before.json()["updated_at"]
        assert after.headers["ETag"] == before.headers["ETag"]


async def test_a_rotation_racing_forced_logins_leaves_no_session_on_the_old_secret(
    live_server: LiveServer, tenant: Tenant
):
    asset = tenant.create_asset("uav")
    name, secret = _credentials(asset)
    body = {"name": name, "secret": secret, "force": True}
    async with httpx.AsyncClient(base_url=live_server.url, timeout=60) as c:
        logins = [c.post("/api/v1/assets/login", json=body) for _ in range(LOGINS)]
        rotation = c.post(
            f"/api/v1/assets/{asset['id']}/config",
            json={"password": "rotated-password-1"},
            headers=tenant.h("admin"),
        )
        # the rotation in the middle of the burst: some logins come before it, some after
        answers = await asyncio.gather(*logins[: LOGINS // 2], rotation, *logins[LOGINS // 2 :])
        rotated = answers.pop(LOGINS // 2)
        assert rotated.status_code == 200, rotated.text
        codes = [r.status_code for r in answers]
        # after the rotation the old secret is wrong (401), and soon throttled (429)
        assert set(codes) <= {200, 401, 429}, [r.text for r in answers]
        tokens = [r.json()["access_token"] for r in answers if r.status_code == 200]
        live = await _live(c, tokens)
        assert live == [], f"{len(live)} sessions opened with the old secret are live ({codes})"
        # the new secret logs in, without force: nothing of the old secret holds the asset
        new = decrypt_config(rotated.content, "rotated-password-1")
        r = await c.post("/api/v1/assets/login", json={"name": name, "secret": new.secret})
        assert r.status_code == 200, r.text


@pytest.mark.parametrize("kind", ["asset", "user"])
async def test_the_database_refuses_a_second_open_session_of_one_account(
    database_url: str, tenant: Tenant, kind: str
):
    """The rule is the database's too (a partial unique index on open sessions): a path that
    forgot it could not leave two sessions of one account open."""
    account = tenant.create_asset("uav")["id"] if kind == "asset" else tenant.user_ids["admin"]
    key = {f"{kind}_id": uuid.UUID(account)}
    now = utcnow()

    def session() -> AuthSession:
        return AuthSession(
            token_hash=uuid.uuid4().hex,
            principal_kind=kind,
            **key,
            expires_at=now + timedelta(hours=1),
            idle_timeout_s=60,
        )

    engine = make_engine(database_url)
    try:
        async with make_sessionmaker(engine)() as db:
            # the tenant's admin has a live session already; the new asset has none yet
            db.add(session())
            if kind == "asset":
                db.add(session())
            with pytest.raises(IntegrityError):
                await db.flush()
            await db.rollback()
    finally:
        await engine.dispose()


async def test_concurrent_logins_without_force_let_one_in(live_server: LiveServer, tenant: Tenant):
    name, secret = _credentials(tenant.create_asset("landing_base"))
    body = {"name": name, "secret": secret}
    async with httpx.AsyncClient(base_url=live_server.url, timeout=60) as c:
        answers = await asyncio.gather(
            *(c.post("/api/v1/assets/login", json=body) for _ in range(LOGINS))
        )
        codes = sorted(r.status_code for r in answers)
        assert codes == [200] + [409] * (LOGINS - 1), codes
        assert {r.json()["error"]["code"] for r in answers if r.status_code == 409} == {
            "session_active"
        }


_USERS = sa.table(
    "users",
    sa.column("id", sa.Uuid()),
    sa.column("email", sa.String()),
    sa.column("password_hash", sa.String()),
    sa.column("is_superuser", sa.Boolean()),
    sa.column("is_active", sa.Boolean()),
    sa.column("created_at", UTCDateTime()),
)
_SESSIONS = sa.table(
    "auth_sessions",
    sa.column("id", sa.Uuid()),
    sa.column("token_hash", sa.String()),
    sa.column("principal_kind", sa.String()),
    sa.column("user_id", sa.Uuid()),
    sa.column("created_at", UTCDateTime()),
    sa.column("last_seen_at", UTCDateTime()),
    sa.column("expires_at", UTCDateTime()),
    sa.column("idle_timeout_s", sa.Integer()),
    sa.column("ended_at", UTCDateTime()),
    sa.column("end_reason", sa.String()),
)


async def test_the_migration_ends_all_but_each_accounts_newest_open_session(
    own_database_url: str,
):
    """Sessions left open side by side before 0011 (the race) are ended, the newest kept."""
    await asyncio.to_thread(migrate.upgrade, own_database_url, "0010")
    users = [uuid.uuid4(), uuid.uuid4()]
    t0 = datetime(2026, 12, 1, tzinfo=UTC)
    sessions = {  # (user, minutes after t0, ended): the first user's three open, one ended
        uuid.uuid4(): (users[0], 1, False),
        uuid.uuid4(): (users[0], 2, False),
        uuid.uuid4(): (users[0], 3, False),
        uuid.uuid4(): (users[0], 4, True),
        uuid.uuid4(): (users[1], 1, False),
    }
    engine = create_async_engine(own_database_url)
    try:
        async with engine.begin() as conn:
            for i, user in enumerate(users):
                await conn.execute(
                    _USERS.insert().values(
                        id=user, email=f"u{i}@m.test", password_hash="x", is_superuser=False,
                        is_active=True, created_at=t0,
                    )
                )  # fmt: skip
            for sid, (user, minutes, ended) in sessions.items():
                at = t0 + timedelta(minutes=minutes)
                await conn.execute(
                    _SESSIONS.insert().values(
                        id=sid, token_hash=sid.hex, principal_kind="user", user_id=user,
                        created_at=at, last_seen_at=at, expires_at=at + timedelta(days=1),
                        idle_timeout_s=60, ended_at=at if ended else None,
                        end_reason="logout" if ended else None,
                    )
                )  # fmt: skip
        await asyncio.to_thread(migrate.upgrade, own_database_url)
        async with engine.connect() as conn:
            rows = (await conn.execute(sa.select(_SESSIONS))).all()
    finally:
        await engine.dispose()
    still_open = {r.id for r in rows if r.ended_at is None}
    newest = [s for s, (u, m, _) in sessions.items() if (u, m) in ((users[0], 3), (users[1], 1))]
    assert still_open == set(newest)
    reasons = {r.id: r.end_reason for r in rows}
    assert sorted(reasons[s] for s in sessions if s not in newest) == [
        "logout",
        "taken_over",
        "taken_over",
    ]


@pytest.fixture
async def own_database_url(database_url: str) -> AsyncIterator[str]:
    """An empty database of this test alone, of the suite's kind (SQLite or PostgreSQL)."""
    if not database_url.startswith("postgresql"):
        with tempfile.TemporaryDirectory(prefix="aerobase-0011-") as tmp:
            yield f"sqlite+aiosqlite:///{tmp}/m.db"
        return
    name = f"m0011_{uuid.uuid4().hex[:10]}"
    admin = create_async_engine(PG_URL_DEFAULT, isolation_level="AUTOCOMMIT")
    async with admin.connect() as conn:
        await conn.execute(sa.text(f'CREATE DATABASE "{name}"'))
    try:
        yield PG_URL_DEFAULT.rsplit("/", 1)[0] + f"/{name}"
    finally:
        async with admin.connect() as conn:
            await conn.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        await admin.dispose()
