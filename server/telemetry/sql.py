"""The default telemetry store: a table in the main database, batched and idempotent inserts."""

from __future__ import annotations

import math
import uuid
from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import delete, select
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from server.kit.time import rfc3339
from server.telemetry import bulk
from server.telemetry.models import TelemetrySample
from server.telemetry.store import Query, Sample, flatten


class SqlTelemetryStore:
    """Telemetry in the `telemetry` table, indexed by (asset, time)."""

    in_database = True

    def __init__(self, sessionmaker: async_sessionmaker[AsyncSession], dialect: str) -> None:
        self.sessionmaker = sessionmaker
        self.dialect = dialect

    async def start(self) -> None:
        """The table comes with the migrations."""

    async def close(self) -> None:
        """Nothing to flush: writes are synchronous."""

    async def ping(self) -> None:
        """The table is in the main database, which readiness checks on its own."""

    async def write(self, samples: Sequence[Sample], db: AsyncSession | None = None) -> None:
        """Insert a batch (one driver-level statement, `bulk.py`); a sample already stored (a
        replay) is skipped. Inside `db`'s transaction when given (the caller commits), else in
        one of its own."""
        if not samples:
            return
        if db is not None:
            await bulk.writer(db).insert_samples(db, samples)
            return
        async with self.sessionmaker() as own:
            await bulk.writer(own).insert_samples(own, samples)
            await own.commit()

    async def _rows(self, q: Query) -> list[TelemetrySample]:
        stmt = (
            select(TelemetrySample)  # unscoped: the caller resolved the asset through its scope
            .where(
                TelemetrySample.asset_id == q.asset_id,
                TelemetrySample.ts >= q.start,
                TelemetrySample.ts < q.end,
            )
            .order_by(TelemetrySample.ts, TelemetrySample.seq)
        )
        if q.every_s is None:
            stmt = stmt.limit(q.limit)
        async with self.sessionmaker() as db:
            return list((await db.execute(stmt)).scalars())

    @staticmethod
    def _pick(stored: dict[str, Any], wanted: Sequence[str] | None) -> dict[str, Any]:
        fields = flatten(stored)  # a payload as sent (or a flat one, stored so before)
        return fields if wanted is None else {k: fields[k] for k in wanted if k in fields}

    async def query(self, q: Query) -> list[dict[str, Any]]:
        """Raw rows, or one row per bucket (mean of numbers, last of the rest)."""
        rows = await self._rows(q)
        if q.every_s is None:
            return [{"ts": rfc3339(r.ts), **self._pick(r.fields, q.fields)} for r in rows]
        return downsample(
            [(r.ts, self._pick(r.fields, q.fields)) for r in rows], q.start, q.every_s, q.agg
        )[: q.limit]

    async def latest(self, asset_id: uuid.UUID) -> dict[str, Any] | None:
        """The newest sample."""
        stmt = (
            select(TelemetrySample)
            .where(TelemetrySample.asset_id == asset_id)  # unscoped: see _rows
            .order_by(TelemetrySample.ts.desc(), TelemetrySample.seq.desc())
            .limit(1)
        )
        async with self.sessionmaker() as db:
            row = (await db.execute(stmt)).scalar_one_or_none()
        return None if row is None else {"ts": rfc3339(row.ts), **flatten(row.fields)}

    async def prune(self, before: datetime) -> int:
        """Delete samples older than `before`."""
        async with self.sessionmaker() as db:
            result = await db.execute(delete(TelemetrySample).where(TelemetrySample.ts < before))
            await db.commit()
        return int(result.rowcount or 0)  # type: ignore[attr-defined]


def downsample(
    rows: Sequence[tuple[datetime, dict[str, Any]]], start: datetime, every_s: float, agg: str
) -> list[dict[str, Any]]:
    """Group rows into `every_s` buckets from `start`: numbers by mean or last, others by last."""
    buckets: dict[int, list[dict[str, Any]]] = {}
    for ts, fields in rows:
        buckets.setdefault(math.floor((ts - start).total_seconds() / every_s), []).append(fields)
    out = []
    for index in sorted(buckets):
        group = buckets[index]
        merged: dict[str, Any] = {}
        for name in {k for f in group for k in f}:
            values = [f[name] for f in group if name in f]
            numeric = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
            if agg == "mean" and numeric and len(numeric) == len(values):
                merged[name] = sum(numeric) / len(numeric)
            else:
                merged[name] = values[-1]
        bucket_start = start.timestamp() + index * every_s
        out.append({"ts": rfc3339(datetime.fromtimestamp(bucket_start, UTC)), **merged})
    return out
