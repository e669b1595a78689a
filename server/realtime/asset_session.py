"""The server half of the link protocol: one connected asset's session on `/ws/asset`.

After hello/welcome the socket delivers each message to `on_text`, synchronously (no task switch
per message); beside it runs command delivery (from the database, woken by a broker nudge or by
the process's command sweep). The process's `AssetKeeper` (keeper.py) keeps the presence claim
and the login session alive for every asset session at once. `on_text`
rate-limits, de-duplicates by seq, fans durable messages out to operators (the received telemetry
re-emitted once with `asset_id` set, not re-serialised from the model) and hands them to the
ingest, which calls back once per batch with the highest seq of this session it stored: the
session acknowledges it with one cumulative ack, at once or, when it acked less than
`ws_ack_interval_s` ago, once that interval is up (nothing is acked before it is stored; a UAV
sending 10 messages a second gets 2 acks a second at the default 0.5 s). A message whose only
fault is a NaN or infinite number is kept without it: the asset is answered `invalid_payload`
naming the field and the asset's events record `telemetry_field_dropped`. A binary frame closes
the socket with 1003 (the socket does), no hello within the handshake time with 4408.
"""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from typing import Any

import structlog
from sqlalchemy.exc import SQLAlchemyError

from asynckit.ratelimit import TokenBucket
from asynckit.tasks import cancel_and_wait
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
from server.realtime.channels import asset_channel, command_channel, presence_key, rtcm_channel
from server.realtime.fastpath import ack_text, operator_text, uav_telemetry
from server.realtime.frames import Disconnected, Refused, Socket, close_on_failure, error_text
from server.realtime.ingest import DROPPED_EVENT, Item
from server.realtime.keeper import HEARTBEAT_S, PRESENCE_TTL_S
from server.services import Services
from server.telemetry.service import StreamOfAnotherAsset

log = logging.getLogger(__name__)
DURABLE = ("telemetry", "event", "command_result")
ASSET_QUEUE = 10_000  # frames that may wait for a slow asset before later ones are dropped


class AssetSession:
    """One asset's live connection, from its presence claim to its close."""

    def __init__(
        self,
        services: Services,
        sock: Socket,
        principal: Principal,
        asset_id: uuid.UUID,
        organization_id: uuid.UUID,
    ) -> None:
        """A session of `principal` (an asset session) over the accepted socket `sock`."""
        self.services = services
        self.sock = sock
        self.principal = principal
        self.session_id = principal.session_id
        self.asset_id = asset_id
        self.organization_id = organization_id
        self.asset_key = str(asset_id)
        self.channel = asset_channel(asset_id)
        self.presence = presence_key(asset_id)
        self.owner = f"{services.hub.node}:{uuid.uuid4().hex[:8]}"
        settings = services.settings
        self.bucket = TokenBucket(settings.ws_rate_per_s, settings.ws_burst)
        self.wake = asyncio.Event()  # commands wait in the database
        self.stream = uuid.UUID(int=0)
        self.last_seq = 0  # the highest seq received (handed to the ingest)
        self.stored_seq = 0  # the highest seq stored
        self.acked = 0  # the highest seq acknowledged (stored and said so)
        self.ack_interval = settings.ws_ack_interval_s
        self._acked_at = -self.ack_interval
        self._ack_timer: asyncio.TimerHandle | None = None
        self.storage_failed = False  # a batch of ours failed: nothing more is acked on this socket
        self._paused = False  # not read while the ingest's queue is long

    async def serve(self) -> None:
        """Claim presence, exchange hello/welcome, then serve until the socket closes."""
        hub, broker = self.services.hub, self.services.broker
        # this connection's task (and the tasks it starts) log with the asset's id
        structlog.contextvars.bind_contextvars(asset_id=self.asset_key)
        if await broker.claim(self.presence, self.owner, PRESENCE_TTL_S) is not None:
            self.sock.close(4409, "another connection of this asset is live")
            return
        hub.register_closer(self.principal.session_id, self.sock.close, kind="asset")
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
            self.sock.deliver(self.on_text)
            hub.keeper.add(self)
            tasks = [asyncio.create_task(self.deliver_commands())]
            close_on_failure(tasks[0], self.sock, "an asset session's command delivery")
            await self.sock.wait_closed()
        except Disconnected:
            pass
        except Refused as refused:
            self.sock.close(refused.code, refused.reason)
        finally:
            hub.keeper.remove(self)
            if self._ack_timer is not None:
                self._ack_timer.cancel()
            await cancel_and_wait(tasks)
            broker.unsubscribe(command_channel(self.asset_id), self._nudge)
            if corrections:
                broker.unsubscribe(corrections, self._forward_rtcm)
            hub.unregister_closer(self.principal.session_id, self.sock.close, kind="asset")
            try:
                await broker.release(self.presence, self.owner)
            except Exception as err:  # the broker away: the key lapses by itself
                log.warning("could not release the presence of %s: %r", self.asset_id, err)
            self.sock.close(1000)

    def _publish_dropped(self, seq: int, kind: str, salvaged: Salvaged) -> None:
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
        self.services.broker.publish_nowait(
            self.channel, {"id": str(event.id), "text": encode(event)}
        )

    def _nudge(self, _message: dict[str, Any]) -> None:
        self.wake.set()

    def _forward_rtcm(self, message: dict[str, Any]) -> None:
        if self.sock.send_text(encode(envelope(RtcmPayload(data=message["data"])))):
            self.services.hub.counters.rtcm_forwarded += 1

    async def _hello(self) -> bool:
        """Read the hello, find where its stream stands, send the welcome; False once closed."""
        raw = await self.sock.receive_text(self.services.settings.ws_handshake_s, "hello")
        hello = decode(raw, "asset_to_server")
        if not isinstance(hello, Hello):
            self.sock.close(1008, "the first message must be hello")
            return False
        self.stream = hello.payload.stream
        try:
            self.last_seq = await self.services.ingest.last_seq(self.stream, self.asset_id)
            self.acked = self.stored_seq = self.last_seq
        except StreamOfAnotherAsset:
            self.sock.close(1008, "that stream belongs to another asset")
            return False
        except SQLAlchemyError as err:  # the database busy or away: the asset retries
            log.warning("stream position of %s unavailable: %r", self.stream, err)
            self.sock.close(1011, "storage unavailable; reconnect and retry")
            return False
        welcome = WelcomePayload(
            session_id=str(self.principal.session_id),
            last_acked_seq=self.last_seq,
            heartbeat_s=HEARTBEAT_S,
            server_time=int(time.time() * 1000),
        )
        self.sock.send_text(encode(envelope(welcome)))
        return True

    def on_text(self, raw: str) -> None:
        """One message from the asset: validate, rate-limit, de-duplicate, fan out and store."""
        hub = self.services.hub
        hub.counters.received += 1
        if not self.bucket.take():
            # Acks are cumulative: storing later messages past a rejected one would lose it. So the
            # excess is refused with an error and the socket closed; the client reconnects and
            # replays from the last ack, at its own pace.
            hub.counters.rate_limited += 1
            self.sock.send_text(
                error_text(
                    "rate_limited",
                    f"over {self.bucket.rate:.0f} messages/s (burst "
                    f"{self.bucket.burst:.0f}): reconnect and replay from the last ack",
                )
            )
            self.sock.close(1008, "rate limit exceeded")
            return
        fast = uav_telemetry(raw, self.asset_id)
        if fast is not None:
            # valid UAV telemetry (the common case): decoded once, encoded for operators and for
            # storage by the mirror, no model built
            if fast.seq <= self.last_seq:
                self._duplicate()
                return
            self._durable(fast.seq, "telemetry", fast.ts, None, {}, fast.text, fast.payload_json)
            return
        decoded = decode(raw, "asset_to_server")
        salvaged = None
        if isinstance(decoded, DecodeError):
            hub.counters.malformed += 1
            if decoded.code == "invalid_payload" and decoded.kind in DURABLE:
                salvaged = drop_non_finite(raw, "asset_to_server")
            if salvaged is None:
                self.sock.send_text(error_text(decoded.code, decoded.message, decoded.seq))
                return
            self.sock.send_text(
                error_text("invalid_payload", _dropped_message(salvaged), decoded.seq)
            )
        msg: Envelope = salvaged.message if salvaged else decoded  # type: ignore[assignment]
        if msg.type in DURABLE:
            if msg.seq <= self.last_seq:
                self._duplicate()
                return
            text, payload = operator_text(raw, msg, salvaged is not None, self.asset_key)
            self._durable(
                msg.seq,
                msg.type,
                msg.ts,
                str(msg.id),
                payload,
                text,
                re=getattr(msg, "re", None),
                dropped=salvaged.dropped if salvaged else (),
            )
            if salvaged:
                self._publish_dropped(msg.seq, msg.type, salvaged)
        elif msg.type == "rtcm":
            self.services.broker.publish_nowait(
                rtcm_channel(self.asset_id), {"data": msg.payload.data}
            )
        elif msg.type == "hello":
            self.sock.send_text(
                error_text("unexpected_hello", "hello is only valid as the first message", msg.seq)
            )

    def _duplicate(self) -> None:
        """A replayed message already stored (or on its way): answered by the ack that covers it."""
        self.services.hub.counters.duplicates += 1
        if self.acked == self.last_seq:  # else a pending ack covers it
            self.sock.send_text(ack_text(self.last_seq))

    def _durable(
        self,
        seq: int,
        kind: str,
        ts: int,
        msg_id: str | None,
        payload: dict[str, Any],
        text: str | bytes,
        payload_json: str | None = None,
        re: uuid.UUID | None = None,
        dropped: tuple[str, ...] = (),
    ) -> None:
        """Fan a new durable message out to operators (encoded once here, not once per operator
        socket) and hand it to the ingest, which acks it once stored. Telemetry goes out without
        its id: it is published on one channel only, so no operator needs to de-duplicate it."""
        self.last_seq = seq
        self.services.broker.publish_nowait(
            self.channel, {"text": text} if msg_id is None else {"id": msg_id, "text": text}
        )
        ingest = self.services.ingest
        ingest.submit(
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
                payload_json=payload_json,
            )
        )
        if ingest.congested and not self._paused:
            # storage is behind: read no more from this asset until it catches up (TCP pushes
            # back; the asset keeps its messages on disk and sends them later)
            self._paused = True
            self.sock.pause_reading()
            ingest.resume_later(self._resume_reading)

    def _resume_reading(self) -> None:
        self._paused = False
        self.sock.resume_reading()

    # --- what the ingest says (Acks) ---

    def stored(self, seq: int) -> None:
        """Every message up to `seq` is stored: one cumulative ack, now or when the ack interval
        since the last one is up."""
        if self.storage_failed or seq <= self.stored_seq:
            return
        self.stored_seq = seq
        if self._ack_timer is None:
            loop = asyncio.get_running_loop()
            wait = self._acked_at + self.ack_interval - loop.time()
            if wait <= 0:
                self._ack()
            else:
                self._ack_timer = loop.call_later(wait, self._ack)

    def _ack(self) -> None:
        self._ack_timer = None
        if self.storage_failed or self.stored_seq <= self.acked:
            return
        self.acked = self.stored_seq
        self._acked_at = asyncio.get_running_loop().time()
        self.sock.send_text(ack_text(self.acked))

    def rejected(self, seq: int, reason: str) -> None:
        """This one message cannot be stored (the others of its batch were): it is refused, and
        acknowledged with the rest so that the asset does not replay it forever."""
        if not self.storage_failed:
            self.sock.send_text(error_text("invalid_payload", reason, seq))
            self.stored(seq)

    def failed(self, err: BaseException) -> None:
        """Storage failed: nothing after this is acked; the asset reconnects and replays."""
        if not self.storage_failed:
            self.storage_failed = True
            self.sock.close(1011, "storage failed; reconnect and replay")

    # --- what the keeper says (keeper.Kept) ---

    def evict(self, code: int, reason: str) -> None:
        """The login session ended, or a newer connection of the asset took over."""
        self.sock.close(code, reason)

    def commands_due(self) -> None:
        """The process's sweep found commands waiting for this asset."""
        self.wake.set()

    async def deliver_commands(self) -> None:
        """Send queued commands (from the database) now and whenever woken: by a nudge through
        the broker, or by the keeper's sweep (a nudge lost in a broker hiccup)."""
        while True:
            self.wake.clear()  # before reading: a nudge arriving meanwhile reads again
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
                    if self.sock.send_text(text):
                        await commands.set_status(db, cmd, "sent", "delivered to the asset")
                await db.commit()
            await self.wake.wait()


def _dropped_message(salvaged: Salvaged) -> str:
    text = "non-finite numbers dropped: " + ", ".join(f"payload.{f}" for f in salvaged.dropped)
    if salvaged.cleared:
        text += " (cleared: " + ", ".join(f"payload.{f}" for f in salvaged.cleared) + ")"
    return text + "; the rest of the message is stored"
