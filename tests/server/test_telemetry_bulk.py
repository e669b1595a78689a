"""The ingest's driver-level writes (server/telemetry/bulk.py) store rows exactly as the ORM does."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

from sqlalchemy import select

import server.models  # noqa: F401  (every table, so foreign keys resolve)
from server.kit.db import make_engine, make_sessionmaker
from server.kit.time import rfc3339
from server.telemetry.bulk import BulkWriter
from server.telemetry.models import TelemetrySample
from server.telemetry.sql import SqlTelemetryStore
from server.telemetry.store import Query, Sample
from tests.conftest import Tenant


def test_sqlite_times_are_the_text_sqlalchemy_writes(tmp_path: Path) -> None:
    """The C-formatted time (a third of the processor's cost) is the processor's text, to the
    microsecond, including whole seconds (which `isoformat` would shorten without timespec)."""
    dialect = make_engine(f"sqlite+aiosqlite:///{tmp_path}/t.db").dialect
    writer = BulkWriter(dialect)
    processor = TelemetrySample.__table__.c.ts.type.dialect_impl(dialect).bind_processor(dialect)
    start = datetime(2026, 1, 1, tzinfo=UTC)
    times = [start + timedelta(microseconds=7919 * k, seconds=k) for k in range(2000)]
    times += [datetime(1970, 1, 1, tzinfo=UTC), datetime(2099, 12, 31, 23, 59, 59, tzinfo=UTC)]
    for t in times:
        assert writer._ts(t) == processor(t)
    # a time in another zone goes through the processor (converted to UTC)
    cet = datetime(2026, 1, 1, 13, 0, tzinfo=timezone(timedelta(hours=1)))
    assert writer._ts(cet) == processor(cet) == "2026-01-01 12:00:00.000000"


async def test_a_batch_is_stored_once_and_read_back_flat(database_url: str, tenant: Tenant) -> None:
    """Samples written through the driver-level insert (the payload nested, as sent) read back
    through the ORM with the same times and flat fields; the same batch again adds nothing."""
    engine = make_engine(database_url)
    try:
        store = SqlTelemetryStore(make_sessionmaker(engine), engine.dialect.name)
        asset = uuid.UUID(tenant.create_asset("uav")["id"])
        t0 = datetime(2026, 11, 26, 12, 0, 0, tzinfo=UTC)
        batch = [
            Sample(
                asset,
                t0 + timedelta(milliseconds=100 * i),
                i + 1,
                {
                    "kind": "uav",
                    "battery": {"percent": 90.0 - i, "voltage_v": None},
                    "armed": True,
                },
            )
            for i in range(5)
        ]
        await store.write(batch)
        await store.write(batch)  # a replay
        rows = await store.query(Query(asset, t0, t0 + timedelta(seconds=1)))
        assert rows == [
            {
                "ts": rfc3339(t0 + timedelta(milliseconds=100 * i)),
                "kind": "uav",
                "battery.percent": 90.0 - i,
                "armed": True,
            }
            for i in range(5)
        ]
        async with make_sessionmaker(engine)() as db:
            stored = (
                (await db.execute(select(TelemetrySample).where(TelemetrySample.asset_id == asset)))
                .scalars()
                .all()
            )
        assert sorted(r.seq for r in stored) == [1, 2, 3, 4, 5]
        assert {r.ts for r in stored} == {s.ts for s in batch}
    finally:
        await engine.dispose()
