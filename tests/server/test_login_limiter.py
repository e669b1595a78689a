"""The failed-login limiter under concurrent successes: logins of one account succeeding at the
same moment (two replicas, rovers sharing an account) clear its failures one after the other,
and none fails (on PostgreSQL, without the account's lock, two of them deadlock)."""

from __future__ import annotations

import asyncio
import uuid

from server.auth.limiter import LoginLimiter
from server.kit.db import make_engine, make_sessionmaker
from server.kit.time import utcnow
from server.kit.uow import unit_of_work
from tests.conftest import test_settings


async def test_successes_of_one_account_at_once_each_clear_without_a_deadlock(database_url):
    settings = test_settings(database_url, login_max_failures_account=1000)
    engine = make_engine(database_url)
    try:
        limiter = LoginLimiter(make_sessionmaker(engine), settings)
        account = f"rovers-{uuid.uuid4().hex[:8]}@example.com"
        for _ in range(5):  # rounds: a deadlock is likely, not certain, in any one of them
            attempts = [await limiter.admit(account, "198.51.100.7", utcnow()) for _ in range(8)]

            async def succeed(attempt):  # type: ignore[no-untyped-def]
                async with unit_of_work(limiter.sessionmaker) as uow:
                    await limiter.succeeded(uow.db, account, None, attempt)

            results = await asyncio.gather(*(succeed(a) for a in attempts), return_exceptions=True)
            assert [r for r in results if r is not None] == []
            again = await limiter.admit(account, None, utcnow())  # the account starts clean
            async with unit_of_work(limiter.sessionmaker) as uow:
                assert len(again.row_ids) == 1
                await limiter.succeeded(uow.db, account, None, again)
    finally:
        await engine.dispose()
