"""A person's live view on `/ws/operator`: subscribe to assets of their organisation, receive what they send."""

from __future__ import annotations

import asyncio
import json
import uuid
from collections import deque
from collections.abc import Iterable
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect

from protocol.codec import DecodeError, decode
from protocol.messages import Subscribe, Unsubscribe
from server.assets.repository import AssetRepository
from server.kit.errors import NotFound
from server.kit.scope import Principal
from server.realtime.channels import asset_channel
from server.realtime.sender import Sender
from server.services import Services

RECENT_IDS = 256  # a run's progress is published on its UAV's and its base's channel


class OperatorSession:
    """One operator socket: its subscriptions and the fan-in of their channels."""

    def __init__(self, services: Services, ws: WebSocket, principal: Principal) -> None:
        """A session of the user `principal` over the accepted socket `ws`."""
        self.services = services
        self.ws = ws
        self.principal = principal
        self.sender = Sender(ws, max_queue=5000)
        self.subscribed: set[uuid.UUID] = set()
        self.recent: deque[str] = deque(maxlen=RECENT_IDS)

    def forward(self, message: dict[str, Any]) -> None:
        """Pass one broker message on to the socket (once, even when it came on two channels)."""
        mid = str(message.get("id", ""))
        if mid and mid in self.recent:
            return
        self.recent.append(mid)
        text = message.get("text")
        if not isinstance(text, str):
            text = json.dumps(message, separators=(",", ":"))
        if self.sender.send_text(text):
            self.services.hub.counters.sent_to_operators += 1
        else:
            self.services.hub.counters.operator_dropped += 1

    async def serve(self) -> None:
        """Read subscribe/unsubscribe requests until the socket closes (or is closed for us)."""
        hub = self.services.hub
        hub.register_closer(self.principal.session_id, self.sender.close)
        send_task = asyncio.create_task(self.sender.run())
        try:
            while True:
                receive = asyncio.create_task(self.ws.receive_text())
                done, _ = await asyncio.wait(
                    [receive, send_task], return_when=asyncio.FIRST_COMPLETED
                )
                if send_task in done:
                    receive.cancel()
                    break
                msg = decode(receive.result(), "operator_to_server")
                if isinstance(msg, DecodeError):
                    self.sender.send_error(msg.code, msg.message)
                elif isinstance(msg, Subscribe):
                    await self.subscribe(msg.payload.asset_ids)
                elif isinstance(msg, Unsubscribe):
                    self.unsubscribe(msg.payload.asset_ids)
        except WebSocketDisconnect:
            pass
        finally:
            send_task.cancel()
            self.unsubscribe(list(self.subscribed))
            hub.unregister_closer(self.principal.session_id, self.sender.close)

    async def subscribe(self, asset_ids: Iterable[uuid.UUID]) -> None:
        """Follow these assets; one the caller may not see is answered with not_found."""
        async with self.services.sessionmaker() as db:
            repo = AssetRepository(db, self.principal)
            for asset_id in asset_ids:
                try:
                    await repo.get(asset_id)
                except NotFound:
                    self.sender.send_error("not_found", f"asset {asset_id} not found")
                    continue
                if asset_id not in self.subscribed:
                    self.subscribed.add(asset_id)
                    self.services.broker.subscribe(asset_channel(asset_id), self.forward)

    def unsubscribe(self, asset_ids: Iterable[uuid.UUID]) -> None:
        """Stop following these assets."""
        for asset_id in asset_ids:
            if asset_id in self.subscribed:
                self.subscribed.discard(asset_id)
                self.services.broker.unsubscribe(asset_channel(asset_id), self.forward)
