"""WebSocket routes: `/ws/asset` (daemons) and `/ws/operator` (people), thin shells over the hub."""

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

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from asynckit.ratelimit import TokenBucket
from protocol.codec import DecodeError, decode, encode
from protocol.messages import (
    AckPayload,
    CommandPayload,
    ErrorPayload,
    Hello,
    RtcmPayload,
    Subscribe,
    Unsubscribe,
    WelcomePayload,
    envelope,
)
from server.assets.models import Asset
from server.assets.repository import AssetRepository
from server.commands import service as commands
from server.deps import principal_of, services_of
from server.kit.errors import AppError, NotFound
from server.kit.scope import Principal
from server.realtime.channels import asset_channel, command_channel, presence_key, rtcm_channel
from server.realtime.ingest import Item
from server.services import Services

log = logging.getLogger(__name__)
router = APIRouter()
HEARTBEAT_S = 15.0  # the asset session idles out after 60 s without one
PRESENCE_TTL_S = 30.0
DURABLE = ("telemetry", "event", "command_result")


def _token(ws: WebSocket) -> str | None:
    scheme, _, value = ws.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return ws.query_params.get("token")


async def _authenticate(ws: WebSocket) -> Principal | None:
    services = services_of(ws.app)
    async with services.sessionmaker() as db:
        try:
            principal, _ = await principal_of(db, services.settings, _token(ws))
            await db.commit()
            return principal
        except AppError as err:
            await ws.accept()
            await ws.close(4401, f"unauthorized: {err.message}"[:120])
            return None


class _Sender:
    """Serialises sends on one socket and closes it from anywhere (broker callbacks included)."""

    def __init__(self, ws: WebSocket, max_queue: int = 1000) -> None:
        self.ws = ws
        self.queue: asyncio.Queue[str | tuple[int, str]] = asyncio.Queue(max_queue)
        self.dropped = 0

    def send_text(self, text: str) -> bool:
        try:
            self.queue.put_nowait(text)
            return True
        except asyncio.QueueFull:
            self.dropped += 1
            return False

    def close(self, code: int, reason: str) -> None:
        with contextlib.suppress(asyncio.QueueFull):
            self.queue.put_nowait((code, reason))

    async def run(self) -> None:
        while True:
            item = await self.queue.get()
            if isinstance(item, tuple):
                with contextlib.suppress(Exception):
                    await self.ws.close(item[0], item[1][:120])
                return
            await self.ws.send_text(item)


@router.websocket("/ws/asset")
async def asset_socket(ws: WebSocket) -> None:
    """A daemon's session: hello/welcome, durable stream with acks, commands, RTCM."""
    principal = await _authenticate(ws)
    if principal is None:
        return
    await ws.accept()
    if principal.kind != "asset":
        await ws.close(4401, "this socket is for assets; operators use /ws/operator")
        return
    asset_id, org_id = principal.asset_id, principal.organization_id
    if asset_id is None or org_id is None:  # every asset session carries both; never expected
        await ws.close(4401, "this asset session has no asset or organisation")
        return
    services = services_of(ws.app)
    hub, broker, ingest, settings = (
        services.hub,
        services.broker,
        services.ingest,
        services.settings,
    )
    key, owner = presence_key(asset_id), f"{hub.node}:{uuid.uuid4().hex[:8]}"
    holder = await broker.claim(key, owner, PRESENCE_TTL_S)
    if holder is not None:
        await ws.close(4409, "another connection of this asset is live")
        return
    sender = _Sender(ws, max_queue=10_000)
    hub.register_closer(principal.session_id, sender.close)
    wake = asyncio.Event()
    tasks: list[asyncio.Task[Any]] = []
    nudge = lambda _m: wake.set()  # noqa: E731
    broker.subscribe(command_channel(asset_id), nudge)
    # a UAV bound to a landing base receives that base's RTK corrections
    async with services.sessionmaker() as db:
        asset = await db.get(Asset, asset_id)
    corrections = rtcm_channel(asset.base_id) if asset is not None and asset.base_id else None

    def forward_rtcm(message: dict[str, Any]) -> None:
        if sender.send_text(encode(envelope(RtcmPayload(data=message["data"])))):
            hub.counters.rtcm_forwarded += 1

    if corrections:
        broker.subscribe(corrections, forward_rtcm)
    try:
        raw = await asyncio.wait_for(ws.receive_text(), 15)
        hello = decode(raw, "asset_to_server")
        if not isinstance(hello, Hello):
            await ws.close(1008, "the first message must be hello")
            return
        stream = hello.payload.stream
        try:
            last = await ingest.last_seq(stream, asset_id)
        except ValueError:
            await ws.close(1008, "that stream belongs to another asset")
            return
        await ws.send_text(
            encode(
                envelope(
                    WelcomePayload(
                        session_id=str(principal.session_id),
                        last_acked_seq=last,
                        heartbeat_s=HEARTBEAT_S,
                        server_time=int(time.time() * 1000),
                    )
                )
            )
        )
        conn = _AssetConn(
            asset_id, org_id, stream, last, sender, settings.ws_rate_per_s, settings.ws_burst
        )
        tasks = [
            asyncio.create_task(sender.run()),
            asyncio.create_task(conn.acker()),
            asyncio.create_task(_heartbeat(services, principal, key, owner, sender)),
            asyncio.create_task(_deliver_commands(services, asset_id, sender, wake)),
        ]
        reader = asyncio.create_task(conn.read(ws, services))
        done, _ = await asyncio.wait([reader, tasks[0]], return_when=asyncio.FIRST_COMPLETED)
        for t in done:
            if t.exception() and not isinstance(t.exception(), WebSocketDisconnect):
                log.warning("asset socket ended: %r", t.exception())
        reader.cancel()
    except (WebSocketDisconnect, TimeoutError):
        pass
    finally:
        for t in tasks:
            t.cancel()
        broker.unsubscribe(command_channel(asset_id), nudge)
        if corrections:
            broker.unsubscribe(corrections, forward_rtcm)
        hub.unregister_closer(principal.session_id, sender.close)
        with contextlib.suppress(Exception):
            await broker.release(key, owner)
        if (
            ws.application_state != WebSocketState.DISCONNECTED
            and ws.client_state != WebSocketState.DISCONNECTED
        ):
            with contextlib.suppress(Exception):
                await ws.close(1000)


class _AssetConn:
    """The reading side of one asset socket: validate, de-duplicate, fan out, store, ack."""

    def __init__(
        self,
        asset_id: uuid.UUID,
        organization_id: uuid.UUID,
        stream: uuid.UUID,
        last_seq: int,
        sender: _Sender,
        rate: float,
        burst: float,
    ) -> None:
        self.asset_id = asset_id
        self.organization_id = organization_id
        self.stream = stream
        self.last_seq = last_seq
        self.sender = sender
        self.bucket = TokenBucket(rate, burst)
        self.pending: deque[tuple[int, asyncio.Future[None]]] = deque()
        self.have_pending = asyncio.Event()

    def _error(self, code: str, message: str, seq: int | None = None) -> None:
        self.sender.send_text(
            encode(envelope(ErrorPayload(code=code, message=message, re_seq=seq)))
        )

    async def read(self, ws: WebSocket, services: Services) -> None:
        hub, broker, ingest = services.hub, services.broker, services.ingest
        asset_id, org_id = self.asset_id, self.organization_id
        while True:
            raw = await ws.receive_text()
            hub.counters.received += 1
            if not self.bucket.take():
                # Acks are cumulative: storing later messages past a rejected one would lose it. So the
                # excess is refused with an error and the socket closed; the client reconnects and
                # replays from the last ack, at its own pace.
                hub.counters.rate_limited += 1
                self._error(
                    "rate_limited",
                    f"over {self.bucket.rate:.0f} messages/s (burst "
                    f"{self.bucket.burst:.0f}): reconnect and replay from the last ack",
                )
                self.sender.close(1008, "rate limit exceeded")
                return
            msg = decode(raw, "asset_to_server")
            if isinstance(msg, DecodeError):
                hub.counters.malformed += 1
                self._error(msg.code, msg.message)
                continue
            if msg.type in DURABLE:
                if msg.seq <= self.last_seq:
                    hub.counters.duplicates += 1
                    if not self.pending:
                        self.sender.send_text(encode(envelope(AckPayload(seq=self.last_seq))))
                    continue
                self.last_seq = msg.seq
                data = msg.model_dump(mode="json")
                data["payload"]["asset_id"] = str(asset_id)
                # encoded once here, not once per operator socket
                await broker.publish(
                    asset_channel(asset_id),
                    {"id": data["id"], "text": json.dumps(data, separators=(",", ":"))},
                )
                fut = ingest.submit(
                    Item(
                        self.stream,
                        asset_id,
                        org_id,
                        msg.seq,
                        msg.type,
                        msg.ts,
                        data["payload"],
                        getattr(msg, "re", None),
                    )
                )
                self.pending.append((msg.seq, fut))
                self.have_pending.set()
            elif msg.type == "rtcm":
                await broker.publish(rtcm_channel(asset_id), {"data": msg.payload.data})
            elif msg.type == "hello":
                self._error("unexpected_hello", "hello is only valid as the first message", msg.seq)

    async def acker(self) -> None:
        """Ack the highest seq whose storage completed, in order."""
        while True:
            await self.have_pending.wait()
            seq, fut = self.pending[0]
            try:
                await fut
            except Exception:
                self.sender.close(1011, "storage failed; reconnect and replay")
                return
            highest = seq
            self.pending.popleft()
            while self.pending and self.pending[0][1].done() and not self.pending[0][1].exception():
                highest = self.pending.popleft()[0]
            if not self.pending:
                self.have_pending.clear()
            self.sender.send_text(encode(envelope(AckPayload(seq=highest))))


async def _heartbeat(
    services: Services, principal: Principal, key: str, owner: str, sender: _Sender
) -> None:
    """Keep the session alive and the presence claim ours while the socket lives."""
    from server.auth.service import SessionService

    rng = random.Random()
    while True:
        # jittered so that a thousand sockets opened together do not all write at once
        await asyncio.sleep(HEARTBEAT_S * rng.uniform(0.8, 1.2))
        async with services.sessionmaker() as db:
            alive = await SessionService(db, services.settings).touch(principal.session_id)
            await db.commit()
        if not alive:
            sender.close(4001, "session ended")
            return
        if not await services.broker.refresh(key, owner, PRESENCE_TTL_S):
            sender.close(4409, "another connection of this asset took over")
            return


async def _deliver_commands(
    services: Services, asset_id: uuid.UUID, sender: _Sender, wake: asyncio.Event
) -> None:
    """Send queued commands (from the database) now and whenever nudged through the broker; a slow,
    jittered sweep covers a nudge lost in a broker hiccup."""
    rng = random.Random()
    while True:
        async with services.sessionmaker() as db:
            for cmd in await commands.due_for_delivery(db, asset_id):
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
                if sender.send_text(text):
                    await commands.set_status(db, cmd, "sent", "delivered to the asset")
            await db.commit()
        wake.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(
                wake.wait(), services.settings.command_sweep_s * rng.uniform(0.5, 1.5)
            )


@router.websocket("/ws/operator")
async def operator_socket(ws: WebSocket) -> None:
    """A person's live view: subscribe to assets of their organisation."""
    principal = await _authenticate(ws)
    if principal is None:
        return
    await ws.accept()
    if principal.kind != "user" or principal.organization_id is None:
        await ws.close(4401, "this socket is for users of an organisation")
        return
    services = services_of(ws.app)
    hub, broker = services.hub, services.broker
    sender = _Sender(ws, max_queue=5000)
    hub.register_closer(principal.session_id, sender.close)
    handlers: dict[uuid.UUID, Any] = {}
    recent: deque[str] = deque(
        maxlen=256
    )  # a run's progress is published on its UAV's and its base's channel

    def forward(message: dict[str, Any]) -> None:
        mid = str(message.get("id", ""))
        if mid and mid in recent:
            return
        recent.append(mid)
        text = message.get("text")
        if not isinstance(text, str):
            text = json.dumps(message, separators=(",", ":"))
        if not sender.send_text(text):
            hub.counters.operator_dropped += 1

    send_task = asyncio.create_task(sender.run())
    try:
        while True:
            receive = asyncio.create_task(ws.receive_text())
            done, _ = await asyncio.wait([receive, send_task], return_when=asyncio.FIRST_COMPLETED)
            if send_task in done:
                receive.cancel()
                break
            raw = receive.result()
            msg = decode(raw, "operator_to_server")
            if isinstance(msg, DecodeError):
                sender.send_text(encode(envelope(ErrorPayload(code=msg.code, message=msg.message))))
                continue
            if isinstance(msg, Subscribe):
                async with services.sessionmaker() as db:
                    repo = AssetRepository(db, principal)
                    for asset_id in msg.payload.asset_ids:
                        try:
                            await repo.get(asset_id)
                        except NotFound:
                            sender.send_text(
                                encode(
                                    envelope(
                                        ErrorPayload(
                                            code="not_found", message=f"asset {asset_id} not found"
                                        )
                                    )
                                )
                            )
                            continue
                        if asset_id not in handlers:
                            handlers[asset_id] = forward
                            broker.subscribe(asset_channel(asset_id), forward)
            elif isinstance(msg, Unsubscribe):
                for asset_id in msg.payload.asset_ids:
                    if handlers.pop(asset_id, None):
                        broker.unsubscribe(asset_channel(asset_id), forward)
    except WebSocketDisconnect:
        pass
    finally:
        send_task.cancel()
        for asset_id in handlers:
            broker.unsubscribe(asset_channel(asset_id), forward)
        hub.unregister_closer(principal.session_id, sender.close)
