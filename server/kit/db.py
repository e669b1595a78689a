"""SQLAlchemy base, naming convention, portable column types and the engine factory."""

from __future__ import annotations

import json
import uuid
from datetime import UTC, datetime
from typing import Any

import orjson
from sqlalchemy import DateTime, MetaData, Select, event
from sqlalchemy.exc import DBAPIError, IntegrityError, StatementError
from sqlalchemy.ext.asyncio import (
    AsyncEngine,
    AsyncSession,
    async_sessionmaker,
    create_async_engine,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column
from sqlalchemy.types import TypeDecorator

NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class UTCDateTime(TypeDecorator[datetime]):
    """A timezone-aware datetime stored as UTC on every backend (SQLite keeps no zone)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime given to a UTC column")
        value = value.astimezone(UTC)
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class Base(DeclarativeBase):
    """Declarative base of every table; relationships must be loaded explicitly."""

    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {datetime: UTCDateTime()}


def new_id() -> uuid.UUID:
    """A new random primary key."""
    return uuid.uuid4()


class IdMixin:
    """A UUID primary key."""

    id: Mapped[uuid.UUID] = mapped_column(primary_key=True, default=new_id)


def json_dumps(value: Any) -> str:
    """JSON columns' encoder: orjson (several times faster than `json.dumps`), falling back to
    the standard library for what orjson refuses (integers past 64 bits, non-string keys)."""
    try:
        return orjson.dumps(value).decode()
    except TypeError:
        return json.dumps(value)


DEADLOCK = "40P01"  # PostgreSQL's deadlock_detected


def sqlstate(err: BaseException) -> str:
    """The SQLSTATE of a database error, found along its causes (asyncpg's, through SQLAlchemy's
    wrappers), or "" when none carries one (SQLite's errors do not)."""
    seen: BaseException | None = err
    for _ in range(5):
        if seen is None:
            return ""
        code = getattr(seen, "sqlstate", None)
        if code:
            return str(code)
        orig = seen.orig if isinstance(seen, StatementError) else None
        seen = orig if isinstance(orig, BaseException) else seen.__cause__
    return ""


async def delete_unless_referred(
    db: AsyncSession, row: Any, referred: Select[Any], in_use: Exception
) -> None:
    """Delete `row` in the current unit of work, or raise `in_use` (a 409) while rows refer to it
    through a RESTRICT foreign key (`referred`: a SELECT EXISTS of them).

    They are looked for first, without locks: a DELETE whose RESTRICT check meets a row locked by
    the run engine waits for it, while the engine's own foreign-key check waits for this row
    (PostgreSQL reports a deadlock). Only a row made in the instant between the look and the
    DELETE can still meet it; that violation, or that deadlock, is the same answer."""
    if await db.scalar(referred):
        raise in_use
    await db.delete(row)
    try:
        await db.flush()
    except IntegrityError as err:
        raise in_use from err
    except DBAPIError as err:
        if sqlstate(err) == DEADLOCK:
            raise in_use from err
        raise


def make_engine(url: str, **kwargs: Any) -> AsyncEngine:
    """An async engine (JSON through `json_dumps`); SQLite gets WAL, foreign keys and a busy
    timeout."""
    kwargs.setdefault("json_serializer", json_dumps)
    if url.startswith("sqlite"):
        kwargs.setdefault("pool_size", 20)
        kwargs.setdefault("max_overflow", 40)
        engine = create_async_engine(url, connect_args={"timeout": 30}, **kwargs)

        @event.listens_for(engine.sync_engine, "connect")
        def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        return engine
    kwargs.setdefault("pool_size", 10)
    kwargs.setdefault("max_overflow", 20)
    kwargs.setdefault("pool_pre_ping", True)
    return create_async_engine(url, **kwargs)


def make_sessionmaker(engine: AsyncEngine) -> async_sessionmaker[AsyncSession]:
    """Sessions that keep loaded attributes after commit."""
    return async_sessionmaker(engine, expire_on_commit=False)
