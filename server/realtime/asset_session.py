"""The server half of the link protocol: one connected asset's session on `/ws/asset`.

After hello/welcome the session runs four tasks beside the reader: the sender (one writer per
socket), the acker (cumulative acks, in order, once storage completed), the heartbeat (keeps the
auth session alive and the presence claim ours) and command delivery (from the database, nudged
through the broker). The reader rate-limits, de-duplicates by seq, fans durable messages out to
operators and hands them to the ingest. A message whose only fault is a NaN or infinite number is
kept without it: the asset is answered `invalid_payload` naming the field and the asset's events
record `telemetry_field_dropped`. A binary frame closes the socket with 1003, no hello within the
handshake time with 4408.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import random
import time
import uuid
from collections import deque
from typing import Any

import structlog
from fastapi import WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from asynckit.ratelimit import TokenBucket
from protocol.codec import DecodeError, Salvaged, decode, drop_non_finite, encode
from protocol.messages import (
    AckPayload,
    CommandPayload,
    Envelope,
    EventPayload,
    Hello,
    RtcmPayload,
    WelcomePayload,
    envelope,
)
from server.assets.models import Asset
from server.commands import service as commands
from server.kit.principal import Principal
from server.kit.uow import unit_of_work
from server.realtime.channels import asset_channel, command_channel, presence_key, rtcm_channel
from server.realtime.frames import Refused, receive_text
from server.realtime.ingest import DROPPED_EVENT, Item, RowRejected
from server.realtime.sender import Sender, SlowReader
from server.services import Services
from server.telemetry.service import StreamOfAnotherAsset

log = logging.getLogger(__name__)
HEARTBEAT_S = 15.0  # the asset session idles out after 60 s without one
# An asset is live on one replica at a time (a key in the broker). A replica killed outright
# cannot give the key back: it lapses after PRESENCE_TTL_S, and only then does a surviving
# replica admit the asset's reconnect, so it is short and refreshed every PRESENCE_REFRESH_S.
PRESENCE_TTL_S = 10.0
PRESENCE_REFRESH_S = 3.0
DURABLE = ("telemetry", "event", "command_result")


class AssetSession:
    """One asset's live connection, from its presence claim to its close."""

    def __init__(
        self,
        services: Services,
        ws: WebSocket,
        principal: Principal,
        asset_id: uuid.UUID,
        organization_id: uuid.UUID,
    ) -> None:
        """A session of `principal` (an asset session) over the accepted socket `ws`."""
        self.services = services
        self.ws = ws
        self.principal = principal
        self.asset_id = asset_id
        self.organization_id = organization_id
        self.presence = presence_key(asset_id)
        self.owner = f"{services.hub.node}:{uuid.uuid4().hex[:8]}"
        settings = services.settings
        self.sender = Sender(ws, max_queue=10_000, timeout_s=settings.ws_send_timeout_s)
        self.bucket = TokenBucket(settings.ws_rate_per_s, settings.ws_burst)
        self.wake = asyncio.Event()  # commands wait in the database
        self.stream = uuid.UUID(int=0)
        self.last_seq = 0
        self.pending: deque[tuple[int, asyncio.Future[None]]] = deque()
        self.have_pending = asyncio.Event()

    async def serve(self) -> None:
        """Claim presence, exchange hello/welcome, then serve until the socket or a task ends."""
        hub, broker = self.services.hub, self.services.broker
        # this connection's task (and the tasks it starts) log with the asset's id
        structlog.contextvars.bind_contextvars(asset_id=str(self.asset_id))
        if await broker.claim(self.presence, self.owner, PRESENCE_TTL_S) is not None:
            await self.ws.close(4409, "another connection of this asset is live")
            return
        hub.register_closer(self.principal.session_id, self.sender.close, kind="asset")
        broker.subscribe(command_channel(self.asset_id), self._nudge)
        # a UAV bound to a landing base receives that base's RTK corrections
        async with self.services.sessionmaker() as db:
            asset = await db.get(Asset, self.asset_id)
        corrections = rtcm_channel(asset.base_id) if asset is not None and asset.base_id else None
        if corrections:
            broker.subscribe(corrections, self._forward_rtcm)
        tasks: list[asyncio.Task[Any]] = []
        try:
            if not await self._hello():
                return
            tasks = [
                asyncio.create_task(self.sender.run()),
                asyncio.create_task(self.acker()),
                asyncio.create_task(self.heartbeat()),
                asyncio.create_task(self.deliver_commands()),
            ]
            reader = asyncio.create_task(self.read())
            tasks.append(reader)
            done, _ = await asyncio.wait([reader, tasks[0]], return_when=asyncio.FIRST_COMPLETED)
            if reader in done and not reader.exception() and tasks[0] not in done:
                # the reader queued a close: let the sender write it (bounded by its timeout)
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(asyncio.shield(tasks[0]), 2 * self.sender.timeout_s)
            for t in done:
                error = t.exception()
                if error is not None and not isinstance(error, WebSocketDisconnect | SlowReader):
                    log.error("asset socket failed", exc_info=error)
        except WebSocketDisconnect:
            pass
        except Refused as refused:
            with contextlib.suppress(Exception):
                await self.ws.close(refused.code, refused.reason)
        finally:
            for t in tasks:
                t.cancel()
            for (
                _,
                fut,
            ) in self.pending:  # nobody acks them now: a storage error is not "unretrieved"
                fut.add_done_callback(_retrieve)
            broker.unsubscribe(command_channel(self.asset_id), self._nudge)
            if corrections:
                broker.unsubscribe(corrections, self._forward_rtcm)
            hub.unregister_closer(self.principal.session_id, self.sender.close, kind="asset")
            with contextlib.suppress(Exception):
                await broker.release(self.presence, self.owner)
            if (
                self.ws.application_state != WebSocketState.DISCONNECTED
                and self.ws.client_state != WebSocketState.DISCONNECTED
            ):
                with contextlib.suppress(Exception):
                    await self.ws.close(1000)

    async def _publish_dropped(self, seq: int, kind: str, salvaged: Salvaged) -> None:
        """Tell the asset's operators what was dropped (the ingest records the same event)."""
        event = envelope(
            EventPayload(
                asset_id=self.asset_id,
                name=DROPPED_EVENT,
                severity="warning",
                message=_dropped_message(salvaged),
                data={"seq": seq, "kind": kind, "fields": list(salvaged.dropped)},
            )
        )
        await self.services.broker.publish(
            asset_channel(self.asset_id), {"id": str(event.id), "text": encode(event)}
        )

    def _nudge(self, _message: dict[str, Any]) -> None:
        self.wake.set()

    def _forward_rtcm(self, message: dict[str, Any]) -> None:
        if self.sender.send_text(encode(envelope(RtcmPayload(data=message["data"])))):
            self.services.hub.counters.rtcm_forwarded += 1

    async def _hello(self) -> bool:
        """Read the hello, find where its stream stands, send the welcome; False once closed."""
        raw = await receive_text(self.ws, self.services.settings.ws_handshake_s, "hello")
        hello = decode(raw, "asset_to_server")
        if not isinstance(hello, Hello):
            await self.ws.close(1008, "the first message must be hello")
            return False
        self.stream = hello.payload.stream
        try:
            self.last_seq = await self.services.ingest.last_seq(self.stream, self.asset_id)
        except StreamOfAnotherAsset:
            await self.ws.close(1008, "that stream belongs to another asset")
            return False
        welcome = WelcomePayload(
            session_id=str(self.principal.session_id),
            last_acked_seq=self.last_seq,
            heartbeat_s=HEARTBEAT_S,
            server_time=int(time.time() * 1000),
        )
        await self.ws.send_text(encode(envelope(welcome)))
        return True

    async def read(self) -> None:
        """Validate, rate-limit, de-duplicate, fan out and store what the asset sends."""
        hub, broker, ingest = self.services.hub, self.services.broker, self.services.ingest
        while True:
            try:
                raw = await receive_text(self.ws)
            except Refused as refused:
                self.sender.close(refused.code, refused.reason)
                return
            hub.counters.received += 1
            if not self.bucket.take():
                # Acks are cumulative: storing later messages past a rejected one would lose it. So the
                # excess is refused with an error and the socket closed; the client reconnects and
                # replays from the last ack, at its own pace.
                hub.counters.rate_limited += 1
                self.sender.send_error(
                    "rate_limited",
                    f"over {self.bucket.rate:.0f} messages/s (burst "
                    f"{self.bucket.burst:.0f}): reconnect and replay from the last ack",
                )
                self.sender.close(1008, "rate limit exceeded")
                return
            decoded = decode(raw, "asset_to_server")
            salvaged = None
            if isinstance(decoded, DecodeError):
                hub.counters.malformed += 1
                if decoded.code == "invalid_payload" and decoded.kind in DURABLE:
                    salvaged = drop_non_finite(raw, "asset_to_server")
                if salvaged is None:
                    self.sender.send_error(decoded.code, decoded.message, decoded.seq)
                    continue
                self.sender.send_error("invalid_payload", _dropped_message(salvaged), decoded.seq)
            msg: Envelope = salvaged.message if salvaged else decoded  # type: ignore[assignment]
            if msg.type in DURABLE:
                if msg.seq <= self.last_seq:
                    hub.counters.duplicates += 1
                    if not self.pending:
                        self.sender.send_text(encode(envelope(AckPayload(seq=self.last_seq))))
                    continue
                self.last_seq = msg.seq
                data = msg.model_dump(mode="json")
                data["payload"]["asset_id"] = str(self.asset_id)
                # encoded once here, not once per operator socket
                await broker.publish(
                    asset_channel(self.asset_id),
                    {"id": data["id"], "text": json.dumps(data, separators=(",", ":"))},
                )
                item = Item(
                    self.stream,
                    self.asset_id,
                    self.organization_id,
                    msg.seq,
                    msg.type,
                    msg.ts,
                    data["payload"],
                    getattr(msg, "re", None),
                    dropped=salvaged.dropped if salvaged else (),
                )
                self.pending.append((msg.seq, ingest.submit(item)))
                self.have_pending.set()
                if salvaged:
                    await self._publish_dropped(msg.seq, msg.type, salvaged)
            elif msg.type == "rtcm":
                await broker.publish(rtcm_channel(self.asset_id), {"data": msg.payload.data})
            elif msg.type == "hello":
                self.sender.send_error(
                    "unexpected_hello", "hello is only valid as the first message", msg.seq
                )

    async def acker(self) -> None:
        """Ack the highest seq whose storage completed, in order."""
        while True:
            await self.have_pending.wait()
            seq, fut = self.pending[0]
            try:
                await fut
            except RowRejected as rejected:
                # this one message cannot be stored (the others of its batch were): it is refused,
                # and acknowledged with the rest so that the asset does not replay it forever
                self.sender.send_error("invalid_payload", str(rejected), seq)
            except Exception:
                self.sender.close(1011, "storage failed; reconnect and replay")
                return
            highest = seq
            self.pending.popleft()
            while self.pending and self.pending[0][1].done() and not self.pending[0][1].exception():
                highest = self.pending.popleft()[0]
            # (a rejected row still pending is reported on its own turn of the loop)
            if not self.pending:
                self.have_pending.clear()
            self.sender.send_text(encode(envelope(AckPayload(seq=highest))))

    async def heartbeat(self) -> None:
        """Keep the session alive and the presence claim ours while the socket lives."""
        from server.auth.service import SessionService

        rng = random.Random()
        touched = time.monotonic()
        while True:
            # jittered so that a thousand sockets opened together do not all write at once
            await asyncio.sleep(PRESENCE_REFRESH_S * rng.uniform(0.8, 1.2))
            if time.monotonic() - touched >= HEARTBEAT_S:
                touched = time.monotonic()
                async with unit_of_work(self.services.sessionmaker) as uow:
                    alive = await SessionService(uow, self.services.settings).touch(
                        self.principal.session_id
                    )
                if not alive:
                    self.sender.close(4001, "session ended")
                    return
            broker = self.services.broker
            if not await broker.refresh(self.presence, self.owner, PRESENCE_TTL_S):
                # our key is gone: taken by a newer connection of this asset (then it is live
                # elsewhere and this one must go), or lapsed because this process stalled past
                # the TTL under load (then nobody holds it and this connection is still the one)
                holder = await broker.claim(self.presence, self.owner, PRESENCE_TTL_S)
                if holder is not None:
                    self.sender.close(4409, "another connection of this asset took over")
                    return
                log.warning("the presence of asset %s had lapsed; claimed again", self.asset_id)

    async def deliver_commands(self) -> None:
        """Send queued commands (from the database) now and whenever nudged through the broker; a
        slow, jittered sweep covers a nudge lost in a broker hiccup."""
        rng = random.Random()
        while True:
            async with self.services.sessionmaker() as db:
                for cmd in await commands.due_for_delivery(db, self.asset_id):
                    text = encode(
                        envelope(
                            CommandPayload(
                                name=cmd.name,
                                params=cmd.params,
                                deadline=int(cmd.deadline.timestamp() * 1000),
                            ),
                            id=cmd.id,
                        )
                    )
                    if self.sender.send_text(text):
                        await commands.set_status(db, cmd, "sent", "delivered to the asset")
                await db.commit()
            self.wake.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(
                    self.wake.wait(), self.services.settings.command_sweep_s * rng.uniform(0.5, 1.5)
                )


def _dropped_message(salvaged: Salvaged) -> str:
    text = "non-finite numbers dropped: " + ", ".join(f"payload.{f}" for f in salvaged.dropped)
    if salvaged.cleared:
        text += " (cleared: " + ", ".join(f"payload.{f}" for f in salvaged.cleared) + ")"
    return text + "; the rest of the message is stored"


def _retrieve(fut: asyncio.Future[None]) -> None:
    if not fut.cancelled():
        fut.exception()
