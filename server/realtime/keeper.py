"""Upkeep of every asset session connected to this process: one job each, not one task per socket.

An asset session needs three things done now and then: its presence claim refreshed (so the asset
is live on one replica only), its login session kept alive (the heartbeat), and a sweep for
commands waiting in the database that a lost broker nudge did not announce. Done by each socket
on its own timers, a thousand idle UAVs cost about a third of a core (a timer, a query and a
Redis call each, every few seconds); here each is one job for the whole process: one pipelined
refresh of every presence key, one read and one UPDATE for every login session, one query for
the assets that have commands due.
"""

from __future__ import annotations

import logging
import uuid
from typing import Protocol

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from server.auth.service import touch_many
from server.commands import service as commands
from server.kit.periodic import Periodic
from server.kit.time import utcnow
from server.realtime.broker import Broker

log = logging.getLogger(__name__)
HEARTBEAT_S = 15.0  # an asset's login session idles out after 60 s without one
# An asset is live on one replica at a time (a key in the broker). A replica killed outright
# cannot give the key back: it lapses after PRESENCE_TTL_S, and only then does a surviving
# replica admit the asset's reconnect, so it is short and refreshed every PRESENCE_REFRESH_S.
PRESENCE_TTL_S = 10.0
PRESENCE_REFRESH_S = 3.0


class Kept(Protocol):
    """What the keeper needs of an asset session."""

    presence: str  # its presence key
    owner: str  # its claim on that key
    asset_id: uuid.UUID
    session_id: uuid.UUID  # its login session

    def evict(self, code: int, reason: str) -> None:
        """Close the socket with this code."""

    def commands_due(self) -> None:
        """Commands wait in the database: deliver them."""


class AssetKeeper:
    """The periodic jobs of every asset session of this process."""

    def __init__(
        self,
        broker: Broker,
        sessionmaker: async_sessionmaker[AsyncSession],
        command_sweep_s: float,
        presence_refresh_s: float = PRESENCE_REFRESH_S,
        heartbeat_s: float = HEARTBEAT_S,
    ) -> None:
        self.broker = broker
        self.sessionmaker = sessionmaker
        self.sessions: dict[str, Kept] = {}  # by owner (one per connection)
        self._jobs = [
            Periodic("asset-presence", self.refresh_presence, presence_refresh_s),
            Periodic("asset-heartbeat", self.touch_sessions, heartbeat_s),
            Periodic("asset-command-sweep", self.sweep_commands, command_sweep_s),
        ]

    def start(self) -> None:
        """Start the jobs."""
        for job in self._jobs:
            job.start()

    async def stop(self) -> None:
        """Stop the jobs."""
        for job in self._jobs:
            await job.stop()

    def add(self, session: Kept) -> None:
        """Keep this session (after its presence claim)."""
        self.sessions[session.owner] = session

    def remove(self, session: Kept) -> None:
        """Forget it (its socket closed)."""
        self.sessions.pop(session.owner, None)

    async def refresh_presence(self) -> None:
        """Extend every presence claim; a claim found gone is taken again unless a newer
        connection of the asset holds it (then this one is evicted with 4409)."""
        kept = list(self.sessions.values())
        if not kept:
            return
        held = await self.broker.refresh_many([(s.presence, s.owner) for s in kept], PRESENCE_TTL_S)
        for session, ours in zip(kept, held, strict=True):
            if ours or session.owner not in self.sessions:
                continue
            # gone: taken by a newer connection of this asset (then it is live elsewhere and
            # this one must go), or lapsed because this process stalled past the TTL under load
            # (then nobody holds it and this connection is still the one)
            holder = await self.broker.claim(session.presence, session.owner, PRESENCE_TTL_S)
            if holder is not None:
                session.evict(4409, "another connection of this asset took over")
            else:
                log.warning("the presence of asset %s had lapsed; claimed again", session.asset_id)

    async def touch_sessions(self) -> None:
        """Keep every asset's login session alive; a socket whose session ended is closed."""
        kept = list(self.sessions.values())
        if not kept:
            return
        async with self.sessionmaker() as db:
            alive = await touch_many(db, list({s.session_id for s in kept}), utcnow())
            await db.commit()
        for session in kept:
            if session.session_id not in alive:
                session.evict(4001, "session ended")

    async def sweep_commands(self) -> None:
        """Wake the sessions whose asset has commands due (a nudge may have been lost)."""
        kept = list(self.sessions.values())
        if not kept:
            return
        async with self.sessionmaker() as db:
            due = await commands.assets_with_commands_due(db, list({s.asset_id for s in kept}))
        for session in kept:
            if session.asset_id in due:
                session.commands_due()
