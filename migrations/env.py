"""Alembic environment: async engines, our metadata, a lock against concurrent upgrades."""

from __future__ import annotations

import asyncio

from alembic import context
from sqlalchemy import pool, text
from sqlalchemy.engine import Connection
from sqlalchemy.ext.asyncio import create_async_engine

import server.models  # noqa: F401  (registers every table)
from server.kit.db import Base

config = context.config
target_metadata = Base.metadata
LOCK_ID = 0x41455242  # "AERB": serialises concurrent upgrades of one PostgreSQL database


def _run(connection: Connection) -> None:
    is_pg = connection.dialect.name == "postgresql"
    if is_pg:
        connection.execute(text(f"SELECT pg_advisory_lock({LOCK_ID})"))
        connection.commit()  # the lock is held by the session, across transactions
    try:
        context.configure(
            connection=connection,
            target_metadata=target_metadata,
            render_as_batch=connection.dialect.name == "sqlite",
            compare_type=True,
        )
        with context.begin_transaction():
            context.run_migrations()
        if connection.in_transaction():
            connection.commit()
    finally:
        if is_pg:
            connection.execute(text(f"SELECT pg_advisory_unlock({LOCK_ID})"))
            connection.commit()


async def _online() -> None:
    engine = create_async_engine(config.get_main_option("sqlalchemy.url"), poolclass=pool.NullPool)
    async with engine.connect() as conn:
        await conn.run_sync(_run)
    await engine.dispose()


if context.is_offline_mode():
    context.configure(
        url=config.get_main_option("sqlalchemy.url"),
        target_metadata=target_metadata,
        literal_binds=True,
    )
    with context.begin_transaction():
        context.run_migrations()
else:
    asyncio.run(_online())
