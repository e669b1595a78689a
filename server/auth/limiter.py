"""Failed-login limits that hold under concurrency: admissions are serialised per key.

An attempt is admitted in one short transaction of its own: take the key (a transaction-scoped
advisory lock per key on PostgreSQL, so every replica queues on it; on SQLite the insert that
follows takes the database's single write lock), record the attempt, count the key's attempts
in the window with its own, and commit — or, past the limit, roll back and answer 429. So each
admission counts every earlier one: however many wrong passwords arrive together, exactly the
first `limit` are checked. A checked attempt that fails leaves its rows as its failures; a
successful login takes them back and clears the account's.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from server.auth.repository import LoginFailureRepository
from server.config import Settings
from server.kit.errors import RateLimited
from server.kit.uow import unit_of_work


@dataclass(frozen=True)
class Attempt:
    """The rows an admitted attempt holds, taken back if it succeeds."""

    row_ids: tuple[uuid.UUID, ...]


class LoginLimiter:
    """Failed logins per key over a sliding window, admitted atomically."""

    def __init__(self, sessionmaker: async_sessionmaker[AsyncSession], settings: Settings) -> None:
        self.sessionmaker = sessionmaker
        self.window = timedelta(seconds=settings.login_window_s)
        self.account_limit = settings.login_max_failures_account
        self.address_limit = settings.login_max_failures_address

    def keys(self, account_key: str, addr: str | None) -> list[tuple[str, int]]:
        """The keys an attempt counts against, each with its limit."""
        keys = [(f"account:{account_key}", self.account_limit)]
        if addr:
            keys.append((f"addr:{addr}", self.address_limit))
        return keys

    async def admit(self, account_key: str, addr: str | None, now: datetime) -> Attempt:
        """Count an attempt; RateLimited (and not counted) when a key is over its limit."""
        keys = self.keys(account_key, addr)
        async with unit_of_work(self.sessionmaker) as uow:
            repo = LoginFailureRepository(uow.db)
            await repo.lock(sorted(k for k, _ in keys))
            ids = await repo.add([k for k, _ in keys], now)
            for key, limit in keys:
                count, oldest = await repo.window(key, now - self.window)
                if count > limit:  # leaving the block with the error rolls this attempt back
                    retry = int(((oldest or now) + self.window - now).total_seconds()) + 1
                    what = "this account" if key.startswith("account:") else "your address"
                    raise RateLimited(
                        f"too many failed logins for {what}; try again in {retry} s",
                        retry_after_s=retry,
                    )
        return Attempt(tuple(ids))

    async def succeeded(self, db: AsyncSession, account_key: str, attempt: Attempt) -> None:
        """A successful login takes its attempt back and clears the account's failures (in the
        caller's unit of work; the address keeps its other failures)."""
        repo = LoginFailureRepository(db)
        # the account's key, as admit takes it: two successes at once (two replicas, two rovers
        # sharing an account) would otherwise each delete a row the other's clear waits for
        await repo.lock([f"account:{account_key}"])
        await repo.delete(list(attempt.row_ids))
        await repo.clear(f"account:{account_key}")
