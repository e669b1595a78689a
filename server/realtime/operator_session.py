"""A person's live view on `/ws/operator`: subscribe to assets of their organisation, receive what they send.

Bounded (frontend_api.md, "Limits of the sockets"): sockets per login session (a slot claimed
through the broker, so the bound holds across replicas), assets followed per socket, messages
per second, time to the first message, time for the peer to take a frame.
"""

from __future__ import annotations

import asyncio
import json
import logging
import random
import uuid
from collections import deque
from collections.abc import Iterable
from typing import Any

from asynckit.ratelimit import TokenBucket
from asynckit.tasks import cancel_and_wait
from protocol.codec import DecodeError, decode
from protocol.messages import Subscribe, Unsubscribe
from server.assets.repository import AssetRepository
from server.kit.principal import Principal
from server.realtime.channels import asset_channel, socket_slot_key
from server.realtime.frames import (
    TOO_MANY,
    Disconnected,
    Refused,
    Socket,
    close_on_failure,
    error_text,
)
from server.services import Services

log = logging.getLogger(__name__)
RECENT_IDS = 256  # a run's progress is published on its UAV's and its base's channel
SLOT_TTL_S = 30.0  # a crashed replica's slots free themselves after this
MAX_LISTED_IDS = 20  # ids named in one not_found error
# frames that may wait for a slow operator before later ones are dropped (5 s of 1,000 UAVs at
# 10 Hz; a peer that takes nothing for ws_send_timeout_s is closed before that matters)
OPERATOR_QUEUE = 50_000


class OperatorSession:
    """One operator socket: its subscriptions and the fan-in of their channels."""

    def __init__(self, services: Services, sock: Socket, principal: Principal) -> None:
        """A session of the user `principal` over the accepted socket `sock`."""
        self.services = services
        self.sock = sock
        self.principal = principal
        self.counters = services.hub.counters
        settings = services.settings
        self.bucket = TokenBucket(settings.ws_operator_rate_per_s, settings.ws_operator_burst)
        self.subscribed: set[uuid.UUID] = set()
        self.recent: deque[str] = deque(maxlen=RECENT_IDS)
        self.recent_set: set[str] = set()  # the same ids, for an O(1) look-up per message
        self.owner = f"{services.hub.node}:{uuid.uuid4().hex[:8]}"
        self.slot: str | None = None

    def forward(self, message: dict[str, Any]) -> None:
        """Pass one broker message on to the socket (once, even when it came on two channels:
        those carry an `id`; telemetry, on one channel only, comes without)."""
        mid = message.get("id")
        if mid:
            mid = str(mid)
            if mid in self.recent_set:
                return
            if len(self.recent) == RECENT_IDS:
                self.recent_set.discard(self.recent[0])
            self.recent.append(mid)
            self.recent_set.add(mid)
        text = message.get("text")
        if text is None:
            text = json.dumps(message, separators=(",", ":"))
        if self.sock.send_text(text):
            self.counters.sent_to_operators += 1
        else:
            self.counters.operator_dropped += 1

    async def serve(self) -> None:
        """Read subscribe/unsubscribe requests until the socket closes (or is closed for us)."""
        hub = self.services.hub
        if not await self._claim_slot():
            limit = self.services.settings.ws_max_sockets_per_session
            self.sock.close(TOO_MANY, f"this session already has {limit} sockets open")
            return
        hub.register_closer(self.principal.session_id, self.sock.close)
        read_task = asyncio.create_task(self.read())
        keep_task = asyncio.create_task(self._keep_slot())
        close_on_failure(read_task, self.sock, "an operator socket")
        try:
            await self.sock.wait_closed()
        finally:
            await cancel_and_wait([read_task, keep_task])
            self.unsubscribe(list(self.subscribed))
            hub.unregister_closer(self.principal.session_id, self.sock.close)
            if self.slot is not None:
                try:
                    await self.services.broker.release(self.slot, self.owner)
                except Exception as err:  # the broker away: the slot lapses by itself
                    log.warning("could not release a socket slot: %r", err)

    async def read(self) -> None:
        """Handle messages until the peer leaves; a refused socket is closed."""
        settings = self.services.settings
        first = True
        try:
            while True:
                # the first message (a subscribe, possibly empty) is due within the handshake time
                timeout = settings.ws_handshake_s if first else None
                raw = await self.sock.receive_text(timeout, "first message (subscribe)")
                first = False
                if not self.bucket.take():
                    self.sock.send_text(
                        error_text(
                            "rate_limited",
                            f"over {self.bucket.rate:g} messages/s (burst {self.bucket.burst:g})",
                        )
                    )
                    raise Refused(TOO_MANY, "message rate limit exceeded")
                msg = decode(raw, "operator_to_server")
                if isinstance(msg, DecodeError):
                    self.services.hub.counters.malformed += 1
                    self.sock.send_text(error_text(msg.code, msg.message, msg.seq))
                elif isinstance(msg, Subscribe):
                    await self.subscribe(msg.payload.asset_ids)
                elif isinstance(msg, Unsubscribe):
                    self.unsubscribe(msg.payload.asset_ids)
        except Refused as refused:
            self.sock.close(refused.code, refused.reason)
        except Disconnected:
            pass

    async def subscribe(self, asset_ids: Iterable[uuid.UUID]) -> None:
        """Follow these assets (one query for all); those the caller may not see are answered with
        one not_found, those past the socket's limit with too_many_subscriptions."""
        wanted = [i for i in dict.fromkeys(asset_ids) if i not in self.subscribed]
        if not wanted:
            return
        async with self.services.sessionmaker() as db:
            visible = await AssetRepository(db, self.principal).visible_ids(wanted)
        missing = [i for i in wanted if i not in visible]
        if missing:
            named = ", ".join(str(i) for i in missing[:MAX_LISTED_IDS])
            more = (
                f" and {len(missing) - MAX_LISTED_IDS} more"
                if len(missing) > MAX_LISTED_IDS
                else ""
            )
            noun = "asset" if len(missing) == 1 else "assets"
            self.sock.send_text(error_text("not_found", f"{noun} {named}{more} not found"))
        room = self.services.settings.ws_max_subscriptions - len(self.subscribed)
        found = [i for i in wanted if i in visible]
        for asset_id in found[: max(room, 0)]:
            self.subscribed.add(asset_id)
            self.services.broker.subscribe(asset_channel(asset_id), self.forward)
        if len(found) > room:
            limit = self.services.settings.ws_max_subscriptions
            self.sock.send_text(
                error_text(
                    "too_many_subscriptions",
                    f"a socket follows at most {limit} assets: "
                    f"{len(found) - max(room, 0)} not followed",
                )
            )

    def unsubscribe(self, asset_ids: Iterable[uuid.UUID]) -> None:
        """Stop following these assets."""
        for asset_id in asset_ids:
            if asset_id in self.subscribed:
                self.subscribed.discard(asset_id)
                self.services.broker.unsubscribe(asset_channel(asset_id), self.forward)

    async def _claim_slot(self) -> bool:
        """Take one of the session's socket slots (shared by every replica through the broker)."""
        broker, limit = self.services.broker, self.services.settings.ws_max_sockets_per_session
        for index in range(limit):
            key = socket_slot_key(self.principal.session_id, index)
            if await broker.claim(key, self.owner, SLOT_TTL_S) is None:
                self.slot = key
                return True
        return False

    async def _keep_slot(self) -> None:
        """Refresh the slot while the socket lives (jittered, well inside its time to live)."""
        rng = random.Random()
        while self.slot is not None:
            await asyncio.sleep(SLOT_TTL_S / 3 * rng.uniform(0.8, 1.2))
            if not await self.services.broker.refresh(self.slot, self.owner, SLOT_TTL_S):
                await self.services.broker.claim(self.slot, self.owner, SLOT_TTL_S)
