"""Fixtures shared by every test folder: services, the database, a live server on a real socket."""

from __future__ import annotations

import os
import socket
import tempfile
import threading
import uuid
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from aerobase.ports import free_port
from tests.polling import wait_for
from tests.priority import pytest_runtest_call  # noqa: F401  (hook: cpu_bound tests at nice 19)
from tests.schedule import (  # noqa: F401  (hooks: the longest files first, durations recorded)
    pytest_collection_modifyitems,
    pytest_configure,
    pytest_runtest_logreport,
    pytest_sessionfinish,
)

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def reachable(host: str, port: int, timeout: float = 1.0) -> bool:
    """True when a TCP connection to host:port succeeds."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def need_service(name: str, host: str, port: int) -> None:
    """Fail in CI (CI=true), skip with a reason elsewhere, when a service is unreachable."""
    if reachable(host, port):
        return
    message = f"{name} is not reachable on {host}:{port}"
    if IN_CI:
        pytest.fail(f"{message} (CI=true: service tests must run)")
    pytest.skip(f"{message}; start it to run this test (in CI this fails instead)")


PG_URL_DEFAULT = "postgresql+asyncpg://postgres@127.0.0.1:5432/test"


def _reset_postgres(url: str) -> None:
    import asyncio

    from sqlalchemy import text
    from sqlalchemy.ext.asyncio import create_async_engine

    async def reset() -> None:
        engine = create_async_engine(url)
        async with engine.begin() as conn:
            await conn.execute(text("DROP SCHEMA IF EXISTS public CASCADE"))
            await conn.execute(text("CREATE SCHEMA public"))
        await engine.dispose()

    asyncio.run(reset())


def _worker_database(url: str) -> str:
    """Under pytest-xdist each worker has a PostgreSQL database of its own (`test_gw0`, ...):
    the session's reset drops the whole schema, which must not pull it from under another worker.
    Created when missing; without xdist the URL is unchanged."""
    import asyncio

    import asyncpg

    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker:
        return url
    base, name = url.rsplit("/", 1)
    own = f"{name}_{worker}"

    async def create() -> None:
        dsn = base.replace("postgresql+asyncpg", "postgresql") + f"/{name}"
        conn = await asyncpg.connect(dsn)
        try:
            if not await conn.fetchval("SELECT 1 FROM pg_database WHERE datname = $1", own):
                await conn.execute(f'CREATE DATABASE "{own}"')
        finally:
            await conn.close()

    asyncio.run(create())
    return f"{base}/{own}"


@pytest.fixture(scope="session")
def database_url() -> Iterator[str]:
    """DATABASE_URL when set (PostgreSQL in CI), else a fresh SQLite file; migrated to head."""
    from server import migrate

    url = os.environ.get("DATABASE_URL")
    if url and url.startswith("postgresql"):
        need_service("PostgreSQL", "127.0.0.1", 5432)
        url = _worker_database(url)
        _reset_postgres(url)
        migrate.upgrade(url)
        yield url
        return
    with tempfile.TemporaryDirectory(prefix="aerobase-test-") as tmp:
        url = f"sqlite+aiosqlite:///{tmp}/test.db"
        migrate.upgrade(url)
        yield url


def test_settings(database_url: str, **overrides: Any):  # type: ignore[no-untyped-def]
    """Server settings for tests: real argon2id with a lighter cost, fast scrypt."""
    from server.config import Settings

    base = dict(
        database_url=database_url,
        environment="test",
        migrate_on_start=False,
        argon2_time_cost=1,
        argon2_memory_kib=8192,
        argon2_parallelism=1,
        config_scrypt_log_n=12,
        login_max_failures_address=10_000,
        log_format="console",
        # the simulated world runs 10x: a UAV on the pad is confirmed within ~2 s wall
        run_timeouts={"confirming": 8.0, "checking": 10.0},
        # several test servers share one database without Redis: nudges do not cross processes
        command_sweep_s=1.0,
    )
    base.update(overrides)
    return Settings(**base)


test_settings.__test__ = False  # type: ignore[attr-defined]


class LiveServer:
    """An `aerobase server` app served by uvicorn on a real socket, in a background thread."""

    def __init__(self, settings: Any, port: int | None = None) -> None:
        import uvicorn

        from server.app import create_app

        self.settings = settings
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        settings.port = self.port
        self.app = create_app(settings)
        from server.cli import uvicorn_options

        # as `aerobase server` serves it (the hot sockets natively, uvloop, the WebSocket limits)
        options = {**uvicorn_options(settings), "host": "127.0.0.1", "port": self.port}
        config = uvicorn.Config(self.app, lifespan="on", **options)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(
            target=self.server.run, name=f"server-{self.port}", daemon=True
        )

    def restarted(self) -> LiveServer:
        """A new server process state (new app, empty memory) on the same port; call after stop()."""
        return LiveServer(self.settings, self.port).start()

    def start(self) -> LiveServer:
        self.thread.start()
        wait_for(lambda: self.server.started, 30, what="server start")
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(15)


@pytest.fixture(scope="session")
def live_server(database_url: str) -> Iterator[LiveServer]:
    """One server for the session (tests isolate themselves by creating their own organisations)."""
    server = LiveServer(test_settings(database_url, ntrip_port=0)).start()  # 0: any free port
    yield server
    server.stop()


@pytest.fixture(scope="session")
def api(live_server: LiveServer) -> Iterator[httpx.Client]:
    """An HTTP client for the live server."""
    with httpx.Client(base_url=live_server.url, timeout=30) as client:
        yield client


SUPERUSER_PASSWORD = "super-secret-password-1"


async def create_superuser(database_url: str, email: str) -> None:
    """A platform superuser, created through the admin service on a migrated database."""
    from server.kit.db import make_engine, make_sessionmaker
    from server.kit.security import Passwords
    from server.organizations.service import create_user

    engine = make_engine(database_url)
    async with make_sessionmaker(engine)() as db:
        await create_user(
            db, Passwords(1, 8192, 1), email=email, password=SUPERUSER_PASSWORD, is_superuser=True
        )
        await db.commit()
    await engine.dispose()


OWN_DATABASE_ROOT = "root@deploy.test"


@pytest.fixture
async def own_database() -> AsyncIterator[str]:
    """A PostgreSQL database of this test alone, whatever the suite's database is (several
    replicas, or a link to it that the test cuts, need PostgreSQL; the session's own server must
    not drive this test's runs), migrated, with the superuser OWN_DATABASE_ROOT."""
    import asyncio

    from sqlalchemy import text
    from sqlalchemy.ext.asyncio import create_async_engine

    from server import migrate

    need_service("PostgreSQL", "127.0.0.1", 5432)
    name = f"deploy_{uuid.uuid4().hex[:12]}"
    admin = create_async_engine(PG_URL_DEFAULT, isolation_level="AUTOCOMMIT")
    async with admin.connect() as conn:
        await conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = PG_URL_DEFAULT.rsplit("/", 1)[0] + f"/{name}"
    try:
        await asyncio.to_thread(migrate.upgrade, url)
        await create_superuser(url, OWN_DATABASE_ROOT)
        yield url
    finally:
        async with admin.connect() as conn:
            await conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        await admin.dispose()


@pytest.fixture(scope="session")
def superuser_email(database_url: str) -> str:
    """A platform superuser, created through the admin service on the real database."""
    import asyncio

    email = f"root-{uuid.uuid4().hex[:8]}@aerobase.test"
    asyncio.run(create_superuser(database_url, email))
    return email


# a small GeoJSON polygon, about 75 m by 110 m
SQUARE = {
    "type": "Polygon",
    "coordinates": [[[8.5, 47.3], [8.501, 47.3], [8.501, 47.301], [8.5, 47.301], [8.5, 47.3]]],
}


class Tenant:
    """An organisation with one logged-in user per role, built through the public API."""

    PASSWORD = "tenant-password-123"

    def __init__(self, api: httpx.Client, superuser_email: str, label: str = "org") -> None:
        self.api = api
        self.name = f"{label}-{uuid.uuid4().hex[:10]}"
        root = login(api, superuser_email, SUPERUSER_PASSWORD, force=True)
        r = api.post("/api/v1/organizations", json={"name": self.name}, headers=auth(root))
        assert r.status_code == 201, r.text
        self.id = r.json()["id"]
        root = login(api, superuser_email, SUPERUSER_PASSWORD, force=True, organization_id=self.id)
        self.emails: dict[str, str] = {}
        self.user_ids: dict[str, str] = {}
        for role in ("admin", "operator", "viewer"):
            email = f"{role}-{uuid.uuid4().hex[:8]}@{self.name}.test"
            r = api.post(
                "/api/v1/users",
                json={"email": email, "password": self.PASSWORD, "role": role},
                headers=auth(root),
            )
            assert r.status_code == 201, r.text
            self.emails[role], self.user_ids[role] = email, r.json()["id"]
        api.post("/api/v1/auth/logout", headers=auth(root))
        self.tokens = {
            role: login(api, email, self.PASSWORD) for role, email in self.emails.items()
        }

    def h(self, role: str = "admin") -> dict[str, str]:
        """Authorization headers of the user with `role`."""
        return auth(self.tokens[role])

    def create_asset(
        self, kind: str = "uav", password: str = "asset-password-123", **extra: Any
    ) -> dict[str, Any]:
        """Register an asset as the admin; returns the response body (with config_file)."""
        body = {
            "name": f"{kind}-{uuid.uuid4().hex[:10]}",
            "kind": kind,
            "password": password,
            **extra,
        }
        r = self.api.post("/api/v1/assets", json=body, headers=self.h("admin"))
        assert r.status_code == 201, r.text
        return dict(r.json())

    def create_mission(self, name: str = "m", **extra: Any) -> dict[str, Any]:
        """Store a mission as the operator: one takeoff item unless `items` are given."""
        body = {"name": name, "items": [{"command": 22, "lat": 47.39, "lon": 8.54, "alt": 20}]}
        r = self.api.post("/api/v1/missions", json={**body, **extra}, headers=self.h("operator"))
        assert r.status_code == 201, r.text
        return dict(r.json())

    def create_zone(self, name: str = "zone", **extra: Any) -> dict[str, Any]:
        """Store an airspace zone as the operator: an exclusion over SQUARE unless told."""
        body = {"name": name, "kind": "exclusion", "geometry": SQUARE, **extra}
        r = self.api.post("/api/v1/airspace/zones", json=body, headers=self.h("operator"))
        assert r.status_code == 201, r.text
        return dict(r.json())


def auth(token: str) -> dict[str, str]:
    """A bearer Authorization header."""
    return {"Authorization": f"Bearer {token}"}


def login(api: httpx.Client, email: str, password: str, **extra: Any) -> str:
    """Log in and return the token (fails the test otherwise)."""
    r = api.post("/api/v1/auth/login", json={"email": email, "password": password, **extra})
    assert r.status_code == 200, r.text
    return str(r.json()["access_token"])


@pytest.fixture
def tenant(api: httpx.Client, superuser_email: str) -> Tenant:
    """A fresh organisation with an admin, an operator and a viewer, all logged in."""
    return Tenant(api, superuser_email)


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository's top folder."""
    return Path(__file__).resolve().parent.parent
