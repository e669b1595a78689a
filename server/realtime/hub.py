"""The per-process hub: live asset and operator connections, wired to the broker and the ingest.

The channels it uses are named in `server.realtime.channels`.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import time
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from protocol.messages import CommandResultPayload, envelope
from server.auth.service import alive_until
from server.commands import service as commands
from server.kit.periodic import Periodic
from server.kit.time import utcnow
from server.realtime.broker import Broker
from server.realtime.channels import asset_channel, sessions_ended_channel
from server.realtime.keeper import AssetKeeper

log = logging.getLogger(__name__)
RECHECK_S = 30.0
RECHECK_AHEAD_S = 10.0


@dataclass
class Counters:
    """What the hub has seen, for metrics and tests."""

    received: int = 0
    duplicates: int = 0
    malformed: int = 0
    rate_limited: int = 0
    operator_dropped: int = 0
    rtcm_forwarded: int = 0
    sent_to_operators: int = 0


async def announce_sessions_ended(broker: Broker, ids: list[uuid.UUID], reason: str) -> None:
    """Tell every process on `broker` to close these sessions' sockets (code 4001, `reason`):
    a hub's own session ends, and the admin CLI's (`aerobase admin set-password`).

    Sockets opened after this moment stay open: after a renewal the same session carries on
    with its new token."""
    if ids:
        await broker.publish(
            sessions_ended_channel(),
            {"ids": [str(i) for i in ids], "reason": reason, "at": time.time()},
        )


class Hub:
    """Connections of this process; everything shared goes through the broker and the database."""

    def __init__(
        self,
        broker: Broker,
        sessionmaker: async_sessionmaker[AsyncSession],
        session_sweep_s: float = 0.25,
        command_sweep_s: float = 20.0,
    ) -> None:
        self.broker = broker
        self.sessionmaker = sessionmaker
        self.node = uuid.uuid4().hex[:12]
        self.counters = Counters()
        # per session: how to close each of its sockets here, and when each was opened (wall clock)
        self.closers: dict[uuid.UUID, list[tuple[Callable[[int, str], None], float]]] = {}
        # per session with a socket here: until when it is known to be alive (None: read it)
        self.deadlines: dict[uuid.UUID, datetime | None] = {}
        self.connected: collections.Counter[str] = collections.Counter()  # live sockets by kind
        self._stopping: set[asyncio.Task[None]] = set()  # held things being stopped (`hold`)
        self._sweeper = Periodic("command-sweeper", self.expire_commands, 1.0)
        self._session_sweeper = Periodic("session-sweeper", self.sweep_sessions, session_sweep_s)
        self.keeper = AssetKeeper(broker, sessionmaker, command_sweep_s)  # the asset sockets'

    async def start(self) -> None:
        """Listen for ended sessions; run the command-deadline and session-expiry sweepers."""
        self.broker.subscribe(sessions_ended_channel(), self._on_sessions_ended)
        self._sweeper.start()
        self._session_sweeper.start()
        self.keeper.start()

    async def stop(self) -> None:
        """Stop the sweepers."""
        await self.keeper.stop()
        await self._session_sweeper.stop()
        await self._sweeper.stop()

    async def sessions_ended(self, ids: list[uuid.UUID], reason: str = "the session ended") -> None:
        """Tell every process to close these sessions' sockets (code 4001)."""
        await announce_sessions_ended(self.broker, ids, reason)

    def _on_sessions_ended(self, message: dict[str, Any]) -> None:
        reason = str(message.get("reason") or "the session ended")
        before = message.get("at")
        for raw in message.get("ids", ()):
            with contextlib.suppress(ValueError):
                self._close(uuid.UUID(raw), reason, before if isinstance(before, float) else None)

    def _close(self, session_id: uuid.UUID, reason: str, before: float | None = None) -> None:
        """Close this session's sockets (those registered before `before`, when given)."""
        kept = []
        for close, since in self.closers.pop(session_id, []):
            if before is not None and since > before:
                kept.append((close, since))
            else:
                close(4001, f"session ended: {reason}")
        if kept:
            self.closers[session_id] = kept
        else:
            self.deadlines.pop(session_id, None)

    def register_closer(
        self, session_id: uuid.UUID, close: Callable[[int, str], None], kind: str = "operator"
    ) -> None:
        """Remember how to close a socket of this session (an `asset` or `operator` socket); the
        sweeper reads the session's expiry soon."""
        self.closers.setdefault(session_id, []).append((close, time.time()))
        self.deadlines.setdefault(session_id, None)
        self.connected[kind] += 1

    def unregister_closer(
        self, session_id: uuid.UUID, close: Callable[[int, str], None], kind: str = "operator"
    ) -> None:
        """Forget a closed socket."""
        self.connected[kind] -= 1
        left = [(c, t) for c, t in self.closers.get(session_id, []) if c != close]
        if left:
            self.closers[session_id] = left
        else:
            self.closers.pop(session_id, None)
            self.deadlines.pop(session_id, None)

    def hold(self, session_id: uuid.UUID, kind: str) -> SessionHold:
        """Something other than a socket that a session holds here (a video viewer, a
        publication): once it `starts`, it is stopped when the session ends, as its sockets close
        (announced ends and expiry alike); it is `released` when it ends on its own."""
        return SessionHold(self, session_id, kind)

    def _spawn(self, step: Awaitable[None]) -> None:
        async def run() -> None:
            try:
                await step
            except Exception:
                log.exception("stopping what an ended session held failed")

        task = asyncio.create_task(run())
        self._stopping.add(task)
        task.add_done_callback(self._stopping.discard)

    async def sweep_sessions(self) -> None:
        """Close the sockets of sessions that expired (TTL or idle) or ended unannounced.

        Each session with a socket here is read again only once its known deadline has passed,
        so the sweep costs nothing while sessions are fresh."""
        now = utcnow()
        if not any(until is None or until <= now for until in self.deadlines.values()):
            return
        # one read for every session due within RECHECK_AHEAD_S as well: the periodic rechecks
        # of a thousand sockets fall due a few a second, and each would be a query of its own
        ahead = now + timedelta(seconds=RECHECK_AHEAD_S)
        due = [sid for sid, until in self.deadlines.items() if until is None or until <= ahead]
        async with self.sessionmaker() as db:
            until = await alive_until(db, due, now)
        for sid in due:
            if sid not in self.closers:
                continue
            deadline = until.get(sid)
            if deadline is None:
                self._close(sid, "the session expired or was ended")
            else:
                # read again at the deadline, and now and then meanwhile: an end nobody announced
                # (the admin CLI, a lost broker message) is noticed within RECHECK_S
                self.deadlines[sid] = min(deadline, now + timedelta(seconds=RECHECK_S))

    async def expire_commands(self) -> None:
        """Every unfinished command past its deadline becomes timed_out; operators hear of it."""
        async with self.sessionmaker() as db:
            expired = await commands.expire(db)
            await db.commit()
        for cmd in expired:
            message = envelope(
                CommandResultPayload(asset_id=cmd.asset_id, status="timed_out", reason=cmd.reason),
                re=cmd.id,
            )
            await self.broker.publish(asset_channel(cmd.asset_id), message.model_dump(mode="json"))


class SessionHold:
    """One thing a session holds in this process, registered with the hub like a socket."""

    def __init__(self, hub: Hub, session_id: uuid.UUID, kind: str) -> None:
        self.hub = hub
        self.session_id = session_id
        self.kind = kind
        self._stop: Callable[[], Awaitable[None]] | None = None
        self._released = False

    def start(self, stop: Callable[[], Awaitable[None]]) -> None:
        """It is running: `stop()` ends it when the session ends (unless released already)."""
        if self._released or self._stop is not None:
            return
        self._stop = stop
        self.hub.register_closer(self.session_id, self._close, self.kind)

    def release(self) -> None:
        """It ended on its own (or was stopped): forget it; idempotent."""
        if self._released:
            return
        self._released = True
        if self._stop is not None:
            self.hub.unregister_closer(self.session_id, self._close, self.kind)

    def _close(self, code: int, reason: str) -> None:
        if self._stop is not None and not self._released:
            self.hub._spawn(self._stop())
