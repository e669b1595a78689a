"""What a page's total costs: one page of an organisation's audit log, read three ways.

`plain`: the page alone (LIMIT 100). `paged`: `server/kit/paging.py` as the API runs it (the page
and its filtered total in one statement). `window`: the same with `count(*) OVER ()` instead of
the scalar subquery, for reference. Prints medians and the ratio to `plain`; never pass/fail.

    DATABASE_URL=postgresql+asyncpg://... .venv/bin/python bench/paging.py [--rows 100000]

The database must be migrated (`aerobase admin migrate`); the bench writes one organisation with
`--rows` audit events and deletes it afterwards.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import time
import uuid
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import delete, func, insert, select

from server.audit.models import AuditEvent
from server.kit.db import make_engine, make_sessionmaker
from server.kit.paging import Page, paginate
from server.organizations.models import Organization


async def run(url: str, rows: int, repeats: int) -> None:
    """Fill, time each way `repeats` times (interleaved), print, clean up."""
    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    org = uuid.uuid4()
    async with sessions() as db:
        db.add(Organization(id=org, name=f"bench-paging-{org.hex[:8]}"))
        await db.flush()
        t0 = datetime.now(UTC)
        batch: list[dict[str, Any]] = []
        for i in range(rows):
            batch.append(
                {
                    "id": uuid.uuid4(),
                    "organization_id": org,
                    "at": t0 - timedelta(seconds=i),
                    "action": "login" if i % 3 else "asset.updated",
                    "actor_kind": "user",
                    "actor_id": "bench",
                    "target": "bench",
                    "client_addr": "127.0.0.1",
                    "details": {"n": i},
                }
            )
            if len(batch) == 5000 or i == rows - 1:
                await db.execute(insert(AuditEvent), batch)
                batch = []
        await db.commit()
    stmt = (
        select(AuditEvent)  # unscoped: a bench of one organisation it made itself
        .where(AuditEvent.organization_id == org)
        .order_by(AuditEvent.at.desc(), AuditEvent.id)
    )

    async def plain() -> None:
        async with sessions() as db:
            (await db.execute(stmt.limit(100))).scalars().all()

    async def paged() -> None:
        async with sessions() as db:
            await paginate(db, stmt, Page(100))

    async def window() -> None:
        async with sessions() as db:
            (await db.execute(stmt.add_columns(func.count().over()).limit(100))).all()

    ways: dict[str, Callable[[], Awaitable[None]]] = {
        "plain": plain,
        "paged": paged,
        "window": window,
    }
    times: dict[str, list[float]] = {name: [] for name in ways}
    try:
        for _ in range(repeats):
            for name, way in ways.items():
                start = time.perf_counter()
                await way()
                times[name].append((time.perf_counter() - start) * 1000)
        base = statistics.median(times["plain"])
        print(f"{engine.dialect.name}, {rows} audit events in one organisation, page of 100")
        for name, ms in times.items():
            median = statistics.median(ms)
            print(f"  {name:7s} median {median:8.2f} ms  ({median / base:5.1f}x plain)")
    finally:
        async with sessions() as db:
            await db.execute(delete(AuditEvent).where(AuditEvent.organization_id == org))
            await db.execute(delete(Organization).where(Organization.id == org))
            await db.commit()
        await engine.dispose()


def main(argv: list[str] | None = None) -> None:
    """Parse the arguments and run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args(argv)
    url = os.environ.get("DATABASE_URL", "sqlite+aiosqlite:///./var/aerobase.db")
    asyncio.run(run(url, args.rows, args.repeats))


if __name__ == "__main__":
    main()
