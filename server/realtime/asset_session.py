"""The server half of the link protocol: one connected asset's session on `/ws/asset`.

After hello/welcome the session runs three tasks beside the reader: the sender's writer (used only
when the socket cannot take a frame at once), the heartbeat (keeps the auth session alive and the
presence claim ours) and command delivery (from the database, nudged through the broker). The
reader rate-limits, de-duplicates by seq, fans durable messages out to operators (the received
telemetry re-emitted once with `asset_id` set, not re-serialised from the model) and hands them to
the ingest, which calls back once per batch with the highest seq of this session it stored: the
session then sends one cumulative ack (nothing is acked before it is stored). A message whose only fault is a NaN or infinite number is
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
from typing import Any

import orjson
import structlog
from fastapi import WebSocket, WebSocketDisconnect
from sqlalchemy.exc import SQLAlchemyError
from starlette.websockets import WebSocketState

from asynckit.ratelimit import TokenBucket
from protocol.codec import DecodeError, Salvaged, decode, drop_non_finite, encode
from protocol.messages import (
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
from server.realtime.fastpath import ack_text, operator_text, uav_telemetry
from server.realtime.frames import Refused, receive_text
from server.realtime.ingest import DROPPED_EVENT, Item
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
        self.last_seq = 0  # the highest seq received (handed to the ingest)
        self.acked = 0  # the highest seq acknowledged (stored)
        self.storage_failed = False  # a batch of ours failed: nothing more is acked on this socket

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
            self.acked = self.last_seq
        except StreamOfAnotherAsset:
            await self.ws.close(1008, "that stream belongs to another asset")
            return False
        except SQLAlchemyError as err:  # the database busy or away: the asset retries
            log.warning("stream position of %s unavailable: %r", self.stream, err)
            await self.ws.close(1011, "storage unavailable; reconnect and retry")
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
        hub, broker = self.services.hub, self.services.broker
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
            fast = uav_telemetry(raw)
            if fast is not None:
                # valid UAV telemetry (the common case): no model built, no re-serialisation
                seq = fast["seq"]
                if seq <= self.last_seq:
                    self._duplicate()
                    continue
                payload = fast["payload"]
                payload["asset_id"] = str(self.asset_id)
                try:
                    text = orjson.dumps(fast).decode()
                except orjson.JSONEncodeError:  # a lone surrogate in a string
                    text = json.dumps(fast, separators=(",", ":"))
                await self._durable(seq, "telemetry", fast["ts"], fast["id"], payload, text)
                continue
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
                    self._duplicate()
                    continue
                text, payload = operator_text(raw, msg, salvaged is not None, str(self.asset_id))
                await self._durable(
                    msg.seq,
                    msg.type,
                    msg.ts,
                    str(msg.id),
                    payload,
                    text,
                    getattr(msg, "re", None),
                    salvaged.dropped if salvaged else (),
                )
                if salvaged:
                    await self._publish_dropped(msg.seq, msg.type, salvaged)
            elif msg.type == "rtcm":
                await broker.publish(rtcm_channel(self.asset_id), {"data": msg.payload.data})
            elif msg.type == "hello":
                self.sender.send_error(
                    "unexpected_hello", "hello is only valid as the first message", msg.seq
                )

    def _duplicate(self) -> None:
        """A replayed message already stored (or on its way): answered by the ack that covers it."""
        self.services.hub.counters.duplicates += 1
        if self.acked == self.last_seq:  # else the pending ack covers it
            self.sender.send_text(ack_text(self.last_seq))

    async def _durable(
        self,
        seq: int,
        kind: str,
        ts: int,
        msg_id: str,
        payload: dict[str, Any],
        text: str,
        re: uuid.UUID | None = None,
        dropped: tuple[str, ...] = (),
    ) -> None:
        """Fan a new durable message out to operators (encoded once here, not once per operator
        socket) and hand it to the ingest, which acks it once stored."""
        self.last_seq = seq
        await self.services.broker.publish(
            asset_channel(self.asset_id), {"id": msg_id, "text": text}
        )
        self.services.ingest.submit(
            Item(
                self.stream,
                self.asset_id,
                self.organization_id,
                seq,
                kind,
                ts,
                payload,
                re,
                dropped=dropped,
                acks=self,
            )
        )

    # --- what the ingest says (Acks) ---

    def stored(self, seq: int) -> None:
        """Every message up to `seq` is stored: one cumulative ack."""
        if not self.storage_failed and seq > self.acked:
            self.acked = seq
            self.sender.send_text(ack_text(seq))

    def rejected(self, seq: int, reason: str) -> None:
        """This one message cannot be stored (the others of its batch were): it is refused, and
        acknowledged with the rest so that the asset does not replay it forever."""
        if not self.storage_failed:
            self.sender.send_error("invalid_payload", reason, seq)
            self.stored(seq)

    def failed(self, err: BaseException) -> None:
        """Storage failed: nothing after this is acked; the asset reconnects and replays."""
        if not self.storage_failed:
            self.storage_failed = True
            self.sender.close(1011, "storage failed; reconnect and replay")

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
