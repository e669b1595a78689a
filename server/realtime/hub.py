"""The per-process hub: live asset and operator connections, wired to the broker and the ingest.

The channels it uses are named in `server.realtime.channels`.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from protocol.messages import CommandResultPayload, envelope
from server.commands import service as commands
from server.kit.periodic import Periodic
from server.realtime.broker import Broker
from server.realtime.channels import asset_channel, sessions_ended_channel

log = logging.getLogger(__name__)


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


class Hub:
    """Connections of this process; everything shared goes through the broker and the database."""

    def __init__(self, broker: Broker, sessionmaker: async_sessionmaker[AsyncSession]) -> None:
        self.broker = broker
        self.sessionmaker = sessionmaker
        self.node = uuid.uuid4().hex[:12]
        self.counters = Counters()
        self.closers: dict[uuid.UUID, list[Callable[[int, str], None]]] = {}
        self.connected: collections.Counter[str] = collections.Counter()  # live sockets by kind
        self._sweeper = Periodic("command-sweeper", self.expire_commands, 1.0)

    async def start(self) -> None:
        """Listen for ended sessions and run the command-deadline sweeper."""
        self.broker.subscribe(sessions_ended_channel(), self._on_sessions_ended)
        self._sweeper.start()

    async def stop(self) -> None:
        """Stop the sweeper."""
        await self._sweeper.stop()

    async def sessions_ended(self, ids: list[Any]) -> None:
        """Tell every process to close these sessions' sockets (code 4001)."""
        if ids:
            await self.broker.publish(sessions_ended_channel(), {"ids": [str(i) for i in ids]})

    def _on_sessions_ended(self, message: dict[str, Any]) -> None:
        for raw in message.get("ids", ()):
            with contextlib.suppress(ValueError):
                for close in self.closers.pop(uuid.UUID(raw), []):
                    close(4001, "session ended: another login took it over or it was logged out")

    def register_closer(
        self, session_id: uuid.UUID, close: Callable[[int, str], None], kind: str = "operator"
    ) -> None:
        """Remember how to close a socket of this session (an `asset` or `operator` socket)."""
        self.closers.setdefault(session_id, []).append(close)
        self.connected[kind] += 1

    def unregister_closer(
        self, session_id: uuid.UUID, close: Callable[[int, str], None], kind: str = "operator"
    ) -> None:
        """Forget a closed socket."""
        self.connected[kind] -= 1
        with contextlib.suppress(KeyError, ValueError):
            self.closers[session_id].remove(close)
            if not self.closers[session_id]:
                del self.closers[session_id]

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
