"""Failed-login limits that hold under concurrency: admissions are serialised per key.

An attempt is admitted in one short transaction of its own: take the key (a transaction-scoped
advisory lock per key on PostgreSQL, so every replica queues on it; on SQLite the insert that
follows takes the database's single write lock), record the attempt, count the key's attempts
in the window with its own, and commit — or, past the limit, roll back and answer 429. So each
admission counts every earlier one: however many wrong passwords arrive together, exactly the
first `limit` are checked. A checked attempt that fails leaves its rows as its failures; a
successful login takes them back and clears the account's.

Failures are counted against the account as a whole only from addresses the account has not
logged in from (within `login_known_client_days`). From an address where it has, they count
against the account *at that address*: wrong passwords sent from anywhere else fill the
account-wide count, which a known client does not read, so they cannot lock out the user or the
rovers that hold the right password (SECURITY.md's threat model). A guesser gets the account
limit per window from unknown addresses, all of them together, plus the limit at each address
the account really uses. The per-address limit applies to every attempt.

A wrong password that was checked already, for the same account from the same address, is
answered again without being counted or hashed (`guesses`, kept in the process): a rover or a
script retrying stale credentials tells a guesser nothing new, and so costs no place under the
limits that the clients with the right password share with it.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from server.auth.guesses import CheckedPasswords
from server.auth.repository import LoginFailureRepository
from server.config import Settings
from server.kit.errors import RateLimited
from server.kit.metrics import LOGINS
from server.kit.time import utcnow
from server.kit.uow import unit_of_work

log = logging.getLogger(__name__)
VERIFIED_S = 24 * 3600.0  # a password that matched a hash is taken as matching it for a day


@dataclass(frozen=True)
class Attempt:
    """The rows an admitted attempt holds, taken back if it succeeds."""

    row_ids: tuple[uuid.UUID, ...]
    # the account key it counted against: the account's, or the account's at an address
    account: str


class LoginLimiter:
    """Failed logins per key over a sliding window, admitted atomically; one per running app
    (`Services.limiter`), which keeps the passwords already checked: the wrong ones (`guesses`)
    and the right ones (`verified`)."""

    def __init__(self, sessionmaker: async_sessionmaker[AsyncSession], settings: Settings) -> None:
        self.sessionmaker = sessionmaker
        self.guesses = CheckedPasswords(ttl_s=settings.login_window_s)  # the wrong ones
        self.verified = CheckedPasswords(ttl_s=VERIFIED_S)  # the right ones, for NTRIP streams
        self.window = timedelta(seconds=settings.login_window_s)
        self.account_limit = settings.login_max_failures_account
        self.address_limit = settings.login_max_failures_address
        self.known_for = timedelta(days=settings.login_known_client_days)

    def keys(self, account_key: str, addr: str | None, *, known: bool) -> list[tuple[str, int]]:
        """The keys an attempt counts against, each with its limit; the account's first."""
        account = f"account:{account_key}" + (f"|at:{addr}" if known else "")
        keys = [(account, self.account_limit)]
        if addr:
            keys.append((f"addr:{addr}", self.address_limit))
        return keys

    @staticmethod
    def outcome(door: str, outcome: str) -> None:
        """Count a check on `/metrics` (`aerobase_logins_total`): door user, asset, ntrip or
        password_change; outcome ok, wrong, repeated or limited."""
        LOGINS.labels(door, outcome).inc()

    def repeated(
        self, door: str, account: str, addr: str | None, password: str, stored: str | None
    ) -> bool:
        """Whether this wrong password was checked against the account's hash `stored` from
        `addr` already (`guesses`): then it is answered wrong at once, counted only as
        `repeated` on `/metrics`."""
        if not self.guesses.known(account, addr, password, stored):
            return False
        self.outcome(door, "repeated")
        return True

    def wrong(
        self, door: str, account: str, addr: str | None, password: str, stored: str | None
    ) -> None:
        """A password checked and found wrong against `stored` (None: no such account)."""
        self.guesses.remember(account, addr, password, stored)
        self.outcome(door, "wrong")

    async def admit(
        self, account_key: str, addr: str | None, now: datetime, *, door: str = "user"
    ) -> Attempt:
        """Count an attempt; RateLimited (and not counted, but as `limited` at `door` on
        `/metrics`) when a key is over its limit. The account is named as its login names it, in
        any case: the key is the lower-case name, as the user lookup matches it (else each
        spelling would have a limit of its own)."""
        async with unit_of_work(self.sessionmaker) as uow:
            return await self.admit_in(uow.db, account_key, addr, now, door=door)

    async def admit_in(
        self,
        db: AsyncSession,
        account_key: str,
        addr: str | None,
        now: datetime,
        *,
        door: str = "user",
    ) -> Attempt:
        """`admit` in the caller's transaction, for a caller that already holds a connection
        (taking a second one from the pool while holding the first deadlocks a burst of such
        callers until the pool's timeout). The attempt counts once that transaction commits, and
        the keys stay locked until then: the caller answers a failure without raising, so that
        the transaction commits it."""
        account_key = account_key.lower()
        repo = LoginFailureRepository(db)
        known = addr is not None and await repo.known(account_key, addr, now - self.known_for)
        keys = self.keys(account_key, addr, known=known)
        await repo.lock(sorted(k for k, _ in keys))
        ids = await repo.add([k for k, _ in keys], now)
        for key, limit in keys:
            count, oldest = await repo.window(key, now - self.window)
            if count > limit:  # the error rolls the caller's transaction, and this attempt, back
                self.outcome(door, "limited")
                retry = int(((oldest or now) + self.window - now).total_seconds()) + 1
                what = "this account" if key.startswith("account:") else "your address"
                raise RateLimited(
                    f"too many failed logins for {what}; try again in {retry} s",
                    retry_after_s=retry,
                )
        return Attempt(tuple(ids), keys[0][0])

    async def succeeded(
        self, db: AsyncSession, account_key: str, addr: str | None, attempt: Attempt
    ) -> None:
        """A successful login takes its attempt back, clears the failures of the account key it
        counted against and marks `addr` known for the account (in the caller's unit of work;
        the address keeps its other failures). A success at a known address leaves the
        account-wide count alone: else each login of the user would give a guesser elsewhere
        a new allowance."""
        repo = LoginFailureRepository(db)
        account_key = account_key.lower()
        # the account's key, as admit takes it: two successes at once (two replicas, two rovers
        # sharing an account) would otherwise each delete a row the other's clear waits for
        await repo.lock([attempt.account])
        await repo.delete(list(attempt.row_ids))
        await repo.clear(attempt.account)
        if addr and len(addr) <= 64:
            await repo.remember(account_key, addr, utcnow())


async def housekeeping(sessionmaker: async_sessionmaker[AsyncSession], settings: Settings) -> int:
    """Drop the failures older than the window and the clients not seen for
    `login_known_client_days`; how many rows went (none of them counts any more)."""
    now = utcnow()
    async with unit_of_work(sessionmaker) as uow:
        repo = LoginFailureRepository(uow.db)
        failures = await repo.prune(now - timedelta(seconds=settings.login_window_s))
        known = await repo.forget_known(now - timedelta(days=settings.login_known_client_days))
    return failures + known


async def housekeeping_loop(
    sessionmaker: async_sessionmaker[AsyncSession], settings: Settings, every_s: float = 600.0
) -> None:
    """`housekeeping` now and every `every_s` seconds, until cancelled; a failed round is logged
    and the next one tried (the tables only grow meanwhile; no limit depends on it)."""
    while True:
        try:
            removed = await housekeeping(sessionmaker, settings)
            if removed:
                log.info("login housekeeping removed %d rows", removed)
        except asyncio.CancelledError:
            raise
        except Exception:
            log.exception("login housekeeping failed")
        await asyncio.sleep(every_s)
