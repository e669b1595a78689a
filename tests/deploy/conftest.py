"""What the deployment tests share: a PostgreSQL database of each test's own, and the programs
the deployment runs (installed by .ci/install-system.sh)."""

from __future__ import annotations

import asyncio
import shutil
import uuid
from collections.abc import AsyncIterator

import pytest
from sqlalchemy import text
from sqlalchemy.ext.asyncio import create_async_engine

from server import migrate
from tests.conftest import IN_CI, PG_URL_DEFAULT, create_superuser, need_service

ROOT_EMAIL = "root@deploy.test"


def program(name: str, package: str) -> str:
    """The path of a program from a Debian package; missing, it fails in CI and skips elsewhere."""
    found = shutil.which(name) or shutil.which(name, path="/usr/sbin:/sbin")
    if found is None:
        message = f"{name} is not installed (Debian's {package} package)"
        if IN_CI:
            pytest.fail(f"{message}; CI=true: .ci/install-system.sh installs it")
        pytest.skip(f"{message}; in CI this fails instead")
    return found


@pytest.fixture
async def own_database() -> AsyncIterator[str]:
    """A PostgreSQL database of this test alone (several replicas need PostgreSQL; the session's
    own server must not drive this test's runs), migrated, with a superuser."""
    need_service("PostgreSQL", "127.0.0.1", 5432)
    name = f"deploy_{uuid.uuid4().hex[:12]}"
    admin = create_async_engine(PG_URL_DEFAULT, isolation_level="AUTOCOMMIT")
    async with admin.connect() as conn:
        await conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = PG_URL_DEFAULT.rsplit("/", 1)[0] + f"/{name}"
    try:
        await asyncio.to_thread(migrate.upgrade, url)
        await create_superuser(url, ROOT_EMAIL)
        yield url
    finally:
        async with admin.connect() as conn:
            await conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        await admin.dispose()
