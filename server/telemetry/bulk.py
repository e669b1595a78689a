"""The ingest's two hot writes as driver-level statements, one per batch and table, and in one
trip to the database where the batch is nothing but telemetry.

Telemetry samples and stream positions are written a few hundred rows at a time, a thousand times
a second at fleet scale: SQLAlchemy's per-row parameter handling cost more than the database's
own work. Here each parameter is converted once by its column's own bind processor (so a row is
stored exactly as the ORM would store it, and read back by it), and the statement goes to the
driver in the caller's transaction (`exec_driver_sql`):

- SQLite: one `executemany` per table (`INSERT ... ON CONFLICT DO NOTHING`; an `UPDATE` per
  stream that only raises `last_seq`).
- PostgreSQL: one statement per table over arrays (`unnest`), so a batch is one round trip.

A replay inserts nothing twice (the unique index on asset, seq, ts) and never moves a stream
position back.

`OneTrip` writers store a batch of plain telemetry (samples and stream positions, atomically) with
one wait on the event loop, whatever else keeps it busy: at 10,000 messages a second an event-loop
iteration can take tens of milliseconds, and a batch that needs eight of them (connection,
cursor, two statements, commit, reset, each a hand-over to a thread or a round trip) falls behind
its own input. SQLite: a connection of its own on a thread of its own runs BEGIN IMMEDIATE, both
statements and COMMIT in one call. PostgreSQL: both statements as one (a data-modifying WITH,
atomic by itself) in autocommit: one round trip.
"""

from __future__ import annotations

import asyncio
import sqlite3
import uuid
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime
from functools import cache
from typing import Any, cast

from sqlalchemy import Column, Table
from sqlalchemy.engine import Dialect
from sqlalchemy.ext.asyncio import AsyncEngine, AsyncSession

from server.telemetry.models import AssetStream, TelemetrySample
from server.telemetry.store import Sample

_SAMPLES = cast(Table, TelemetrySample.__table__)
_STREAMS = cast(Table, AssetStream.__table__)

_SQLITE_INSERT = (
    "INSERT INTO telemetry (asset_id, ts, seq, fields) VALUES (?, ?, ?, ?) "
    "ON CONFLICT (asset_id, ts, seq) DO NOTHING"
)
_SQLITE_ADVANCE = "UPDATE asset_streams SET last_seq = ? WHERE stream_id = ? AND last_seq < ?"
_PG_INSERT = (
    "INSERT INTO telemetry (asset_id, ts, seq, fields) "
    "SELECT * FROM unnest($1::uuid[], $2::timestamptz[], $3::bigint[], $4::json[]) "
    "ON CONFLICT (asset_id, ts, seq) DO NOTHING"
)
_PG_BOTH = (  # one statement: a data-modifying WITH always runs, with the main one, atomically
    "WITH inserted AS ("
    "INSERT INTO telemetry (asset_id, ts, seq, fields) "
    "SELECT * FROM unnest($1::uuid[], $2::timestamptz[], $3::bigint[], $4::json[]) "
    "ON CONFLICT (asset_id, ts, seq) DO NOTHING) "
    "UPDATE asset_streams AS s SET last_seq = v.seq "
    "FROM unnest($5::uuid[], $6::bigint[]) AS v(sid, seq) "
    "WHERE s.stream_id = v.sid AND s.last_seq < v.seq"
)
_PG_ADVANCE = (
    "UPDATE asset_streams AS s SET last_seq = v.seq "
    "FROM unnest($1::uuid[], $2::bigint[]) AS v(sid, seq) "
    "WHERE s.stream_id = v.sid AND s.last_seq < v.seq"
)


def _processor(column: Column[Any], dialect: Dialect) -> Callable[[Any], Any]:
    process = column.type.dialect_impl(dialect).bind_processor(dialect)
    return process if process is not None else (lambda value: value)


class BulkWriter:
    """The two statements for one dialect, with its columns' converters."""

    def __init__(self, dialect: Dialect) -> None:
        """Converters of the dialect the engine runs (its JSON serialiser included)."""
        self.postgres = dialect.name == "postgresql"
        self._asset = _processor(_SAMPLES.c.asset_id, dialect)
        self._ts_column = _processor(_SAMPLES.c.ts, dialect)
        self._stream = _processor(_STREAMS.c.stream_id, dialect)
        self._sqlite = dialect.name == "sqlite"

    def _ts(self, ts: datetime) -> Any:
        """The column's representation of `ts`: on SQLite, a UTC time is formatted in C to the
        very text SQLAlchemy's DATETIME writes (YYYY-MM-DD HH:MM:SS.ffffff; a test compares the
        two), a third of the cost of its processor; anything else goes through the processor."""
        if self._sqlite and ts.tzinfo is UTC:
            return ts.replace(tzinfo=None).isoformat(" ", "microseconds")
        return self._ts_column(ts)

    async def insert_samples(self, db: AsyncSession, samples: Sequence[Sample]) -> None:
        """Insert samples in `db`'s transaction; one already stored (a replay) is skipped."""
        if not samples:
            return
        asset, ts = self._asset, self._ts
        conn = await db.connection()
        if self.postgres:
            columns = (
                [s.asset_id for s in samples],
                [ts(s.ts) for s in samples],
                [s.seq for s in samples],
                [s.json() for s in samples],
            )
            await conn.exec_driver_sql(_PG_INSERT, columns)
            return
        params = [(asset(s.asset_id), ts(s.ts), s.seq, s.json()) for s in samples]
        await conn.exec_driver_sql(_SQLITE_INSERT, params)

    async def advance_streams(self, db: AsyncSession, highest: Mapping[uuid.UUID, int]) -> None:
        """Raise each stream's `last_seq` to `highest[stream]` where it is lower, in `db`'s
        transaction (unscoped: streams of connected, authenticated assets)."""
        if not highest:
            return
        conn = await db.connection()
        if self.postgres:
            await conn.exec_driver_sql(_PG_ADVANCE, (list(highest), list(highest.values())))
            return
        stream = self._stream
        params = [(seq, stream(sid), seq) for sid, seq in highest.items()]
        await conn.exec_driver_sql(_SQLITE_ADVANCE, params)


@cache
def _writer(dialect: Dialect) -> BulkWriter:
    return BulkWriter(dialect)


def writer(db: AsyncSession) -> BulkWriter:
    """The writer for the dialect `db` runs on (built once per engine)."""
    return _writer(db.get_bind().dialect)


class SqliteOneTrip:
    """One batch, one call on the writer's own thread and SQLite connection."""

    def __init__(self, path: str, dialect: Dialect) -> None:
        """Write to the database file at `path` (WAL, as the engine set it up)."""
        self.path = path
        self.writer = BulkWriter(dialect)
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="ingest-sqlite")
        self._conn: sqlite3.Connection | None = None

    async def store(self, samples: Sequence[Sample], highest: Mapping[uuid.UUID, int]) -> None:
        """Insert the samples and raise the stream positions in one transaction."""
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._thread, self._write, samples, dict(highest))

    def _write(self, samples: Sequence[Sample], highest: dict[uuid.UUID, int]) -> None:
        conn = self._conn or self._open()
        w = self.writer
        rows = [(w._asset(s.asset_id), w._ts(s.ts), s.seq, s.json()) for s in samples]
        positions = [(seq, w._stream(sid), seq) for sid, seq in highest.items()]
        conn.execute("BEGIN IMMEDIATE")
        try:
            if rows:
                conn.executemany(_SQLITE_INSERT, rows)
            if positions:
                conn.executemany(_SQLITE_ADVANCE, positions)
            conn.execute("COMMIT")
        except BaseException:
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            raise

    def _open(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.path, timeout=30, isolation_level=None)
        conn.execute("PRAGMA foreign_keys=ON")
        conn.execute("PRAGMA busy_timeout=30000")
        self._conn = conn
        return conn

    async def close(self) -> None:
        """Close the connection on its thread, then the thread."""
        loop = asyncio.get_running_loop()
        if self._conn is not None:
            await loop.run_in_executor(self._thread, self._conn.close)
            self._conn = None
        self._thread.shutdown(wait=False)


class PostgresOneTrip:
    """One batch, one statement in autocommit: one round trip."""

    def __init__(self, engine: AsyncEngine) -> None:
        """Write through `engine` (a small pool of the ingest's own)."""
        self.engine = engine
        self.writer = BulkWriter(engine.dialect)

    async def store(self, samples: Sequence[Sample], highest: Mapping[uuid.UUID, int]) -> None:
        """Insert the samples and raise the stream positions in one statement."""
        ts = self.writer._ts
        params = (
            [s.asset_id for s in samples],
            [ts(s.ts) for s in samples],
            [s.seq for s in samples],
            [s.json() for s in samples],
            list(highest),
            list(highest.values()),
        )
        async with self.engine.connect() as conn:
            conn = await conn.execution_options(isolation_level="AUTOCOMMIT")
            await conn.exec_driver_sql(_PG_BOTH, params)

    async def close(self) -> None:
        """The engine is the caller's."""


OneTrip = SqliteOneTrip | PostgresOneTrip
