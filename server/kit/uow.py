"""One unit of work per request, message or job: services stage, the boundary commits once.

Services flush, they never commit. What must happen only once the transaction is durable — telling
every replica that sessions ended (so their sockets close), nudging the process that holds an
asset's socket — is registered on the unit of work as an after-commit hook. `commit()` runs the
hooks after a successful commit; `rollback()` drops them, so nothing is announced that did not
happen. A hook that fails is logged: the commit stands and the caller still gets its answer.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from contextlib import asynccontextmanager

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

log = logging.getLogger(__name__)

AfterCommit = Callable[[], Awaitable[None]]
# called with the ids of sessions that ended (logout, takeover, renewal, a disabled account, ...)
# and why, in words for the people whose sockets close
SessionEndListener = Callable[[list[uuid.UUID], str], Awaitable[None]]


class UnitOfWork:
    """A database session and what to do once its transaction has committed."""

    def __init__(
        self,
        db: AsyncSession,
        *,
        client_addr: str | None = None,
        session_end_listeners: Iterable[SessionEndListener] = (),
    ) -> None:
        """Wrap `db`; `client_addr` is the caller's address (for the audit log)."""
        self.db = db
        self.client_addr = client_addr
        self._listeners = tuple(session_end_listeners)
        self._hooks: list[AfterCommit] = []
        self._ended: dict[str, list[uuid.UUID]] = {}

    def after_commit(self, hook: AfterCommit) -> None:
        """Run `hook` once this unit of work has committed (never when it rolls back)."""
        self._hooks.append(hook)

    def sessions_ended(self, ids: Iterable[uuid.UUID], reason: str) -> None:
        """These sessions end in this transaction: tell the session-end listeners after commit."""
        self._ended.setdefault(reason, []).extend(ids)

    async def commit(self) -> None:
        """Commit, then run the after-commit hooks (session ends first)."""
        await self.db.commit()
        ended, self._ended = self._ended, {}
        hooks, self._hooks = self._hooks, []
        for reason, ids in ended.items():
            for listener in self._listeners:
                await self._run(listener(list(ids), reason))
        for hook in hooks:
            await self._run(hook())

    async def rollback(self) -> None:
        """Roll back and forget the hooks: what they would announce did not happen."""
        self._hooks.clear()
        self._ended.clear()
        await self.db.rollback()

    @staticmethod
    async def _run(step: Awaitable[None]) -> None:
        try:
            await step
        except Exception:  # the transaction is durable whatever a hook does
            log.exception("an after-commit hook failed")


@asynccontextmanager
async def unit_of_work(
    sessionmaker: async_sessionmaker[AsyncSession],
    *,
    client_addr: str | None = None,
    session_end_listeners: Iterable[SessionEndListener] = (),
) -> AsyncIterator[UnitOfWork]:
    """A unit of work on a new session: committed when the block succeeds, rolled back otherwise."""
    async with sessionmaker() as db:
        uow = UnitOfWork(db, client_addr=client_addr, session_end_listeners=session_end_listeners)
        try:
            yield uow
        except BaseException:
            await uow.rollback()
            raise
        await uow.commit()
