"""All SQL of sessions, failed logins and known login clients (identity lookups: not
organisation-scoped)."""

from __future__ import annotations

import uuid
from datetime import datetime

from sqlalchemy import delete, func, select, update
from sqlalchemy.ext.asyncio import AsyncSession

from server.auth.models import AuthSession, KnownLoginClient, LoginFailure


class SessionRepository:
    """Sessions by token hash and by account."""

    def __init__(self, db: AsyncSession) -> None:
        self.db = db

    async def by_token_hash(self, token_hash: str) -> AuthSession | None:
        """The session holding this token, ended or not."""
        stmt = select(AuthSession).where(
            AuthSession.token_hash == token_hash
        )  # unscoped: identity lookup
        return (await self.db.execute(stmt)).scalar_one_or_none()

    async def by_id(self, session_id: uuid.UUID) -> AuthSession | None:
        """The session with this id."""
        return await self.db.get(AuthSession, session_id)

    async def by_ids(self, ids: list[uuid.UUID]) -> list[AuthSession]:
        """The sessions with these ids (those that exist)."""
        stmt = select(AuthSession).where(AuthSession.id.in_(ids))  # unscoped: identity lookup
        return list((await self.db.execute(stmt)).scalars())

    async def mark_seen(self, ids: list[uuid.UUID], now: datetime) -> None:
        """Set `last_seen_at` of these sessions to `now` (one statement)."""
        if ids:
            # unscoped: identity upkeep of sessions this process holds sockets of
            await self.db.execute(
                update(AuthSession).where(AuthSession.id.in_(ids)).values(last_seen_at=now)
            )

    async def open_for(
        self, *, user_id: uuid.UUID | None = None, asset_id: uuid.UUID | None = None
    ) -> list[AuthSession]:
        """Sessions of one account that have not been ended (they may have expired)."""
        stmt = select(AuthSession).where(
            AuthSession.ended_at.is_(None)
        )  # unscoped: identity lookup
        if user_id is not None:
            stmt = stmt.where(AuthSession.user_id == user_id)
        else:
            stmt = stmt.where(AuthSession.asset_id == asset_id)
        return list((await self.db.execute(stmt)).scalars())

    def add(self, session: AuthSession) -> None:
        """Stage a new session."""
        self.db.add(session)


class LoginFailureRepository:
    """Counting failed logins per key inside a time window."""

    def __init__(self, db: AsyncSession) -> None:
        self.db = db

    async def window(self, key: str, since: datetime) -> tuple[int, datetime | None]:
        """How many failures of `key` since `since`, and the oldest of them."""
        stmt = select(func.count(), func.min(LoginFailure.at)).where(  # unscoped: rate limiting
            LoginFailure.key == key, LoginFailure.at >= since
        )
        count, oldest = (await self.db.execute(stmt)).one()
        if oldest is not None and oldest.tzinfo is None:
            from datetime import UTC

            oldest = oldest.replace(tzinfo=UTC)
        return int(count), oldest

    async def lock(self, keys: list[str]) -> None:
        """Hold these keys until the transaction ends (PostgreSQL advisory locks, taken in the
        order given; SQLite has one writer at a time, which serialises the insert that follows)."""
        if self.db.get_bind().dialect.name == "postgresql":
            for key in keys:
                lock = func.pg_advisory_xact_lock(func.hashtext(key))
                await self.db.execute(select(lock))  # unscoped: a lock, no table

    async def add(self, keys: list[str], at: datetime) -> list[uuid.UUID]:
        """Record one attempt against each key; the new rows' ids."""
        rows = [LoginFailure(key=k, at=at) for k in keys]
        self.db.add_all(rows)
        await self.db.flush()
        return [r.id for r in rows]

    async def delete(self, ids: list[uuid.UUID]) -> None:
        """Take these attempts back."""
        if ids:
            await self.db.execute(delete(LoginFailure).where(LoginFailure.id.in_(ids)))

    async def clear(self, key: str) -> None:
        """Forget the failures of one key (after a successful login)."""
        await self.db.execute(delete(LoginFailure).where(LoginFailure.key == key))

    async def prune(self, before: datetime) -> int:
        """Drop failures older than every window; how many went."""
        result = await self.db.execute(delete(LoginFailure).where(LoginFailure.at < before))
        return int(result.rowcount or 0)  # type: ignore[attr-defined]

    async def known(self, account_key: str, addr: str, since: datetime) -> bool:
        """Whether `account_key` logged in from `addr` since `since`."""
        stmt = select(KnownLoginClient.last_success_at).where(  # unscoped: rate limiting
            KnownLoginClient.account_key == account_key,
            KnownLoginClient.addr == addr,
            KnownLoginClient.last_success_at >= since,
        )
        return (await self.db.execute(stmt)).first() is not None

    async def remember(self, account_key: str, addr: str, at: datetime) -> None:
        """Note a login of `account_key` from `addr` at `at` (one row per pair, the latest)."""
        dialect = self.db.get_bind().dialect.name
        if dialect == "postgresql":
            from sqlalchemy.dialects.postgresql import insert
        else:
            from sqlalchemy.dialects.sqlite import insert  # type: ignore[assignment]
        stmt = insert(KnownLoginClient).values(
            account_key=account_key, addr=addr, last_success_at=at
        )
        await self.db.execute(
            stmt.on_conflict_do_update(
                index_elements=["account_key", "addr"], set_={"last_success_at": at}
            )
        )

    async def forget_known(self, before: datetime) -> int:
        """Drop the clients not seen since `before`; how many went."""
        stale = KnownLoginClient.last_success_at < before
        result = await self.db.execute(delete(KnownLoginClient).where(stale))
        return int(result.rowcount or 0)  # type: ignore[attr-defined]
