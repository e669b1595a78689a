"""Migrations: upgrade, downgrade to base, upgrade again; models and migrations agree."""

from __future__ import annotations

import asyncio
import os
import tempfile

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy.ext.asyncio import create_async_engine

from server import migrate
from server.kit.db import Base
from tests.conftest import PG_URL_DEFAULT, _reset_postgres, need_service


def _diff(url: str) -> list:
    import server.models  # noqa: F401

    async def run() -> list:
        engine = create_async_engine(url)
        async with engine.connect() as conn:
            diff = await conn.run_sync(
                lambda c: compare_metadata(MigrationContext.configure(c), Base.metadata)
            )
        await engine.dispose()
        return diff

    return asyncio.run(run())


def _cycle(url: str) -> None:
    migrate.upgrade(url)
    assert _diff(url) == [], "models and migrations disagree: run alembic revision --autogenerate"
    migrate.downgrade(url, "base")
    migrate.upgrade(url)
    assert _diff(url) == []


@pytest.mark.slow
def test_sqlite_upgrade_downgrade_upgrade_and_no_autogenerate_diff():
    with tempfile.TemporaryDirectory() as tmp:
        _cycle(f"sqlite+aiosqlite:///{tmp}/m.db")


@pytest.mark.slow
def test_postgresql_upgrade_downgrade_upgrade_and_no_autogenerate_diff():
    need_service("PostgreSQL", "127.0.0.1", 5432)
    url = os.environ.get(
        "AEROBASE_MIGRATION_TEST_PG_URL", PG_URL_DEFAULT.replace("/test", "/postgres")
    )
    # a database of its own, so the suite's live server (which may use /test) is not disturbed
    import asyncpg

    async def make_db() -> None:
        conn = await asyncpg.connect("postgresql://postgres@127.0.0.1:5432/postgres")
        await conn.execute("DROP DATABASE IF EXISTS aerobase_migrations")
        await conn.execute("CREATE DATABASE aerobase_migrations")
        await conn.close()

    asyncio.run(make_db())
    url = "postgresql+asyncpg://postgres@127.0.0.1:5432/aerobase_migrations"
    _reset_postgres(url)
    _cycle(url)
