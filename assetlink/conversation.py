"""One WebSocket connection of a link: hello, welcome, replay, then live traffic.

The conversation sends the outbox in order (numbering entries as it takes them, at most
`window` unacked), deletes what the server acks, routes inbound commands and RTCM, pings
every heartbeat and gives up on a missing pong. It ends by raising `LinkClosed`.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from collections import Counter
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from assetlink.dispatch import CommandDispatcher
from assetlink.outbox import AsyncOutbox
from asynckit.ratelimit import TokenBucket
from asynckit.tasks import cancel_and_wait
from protocol.codec import DecodeError, decode, encode
from protocol.messages import Ack, Command, Error, HelloPayload, Rtcm, Welcome, envelope

log = logging.getLogger(__name__)

RtcmCallback = Callable[[bytes], Awaitable[None] | None]


class SessionEnded(Exception):
    """The server ended the session (or refused the token): log in again."""


class LinkClosed(Exception):
    """The WebSocket closed; `code` is its close code (1006 when none was received)."""

    def __init__(self, code: int, reason: str = ""):
        """Keep the close code and reason."""
        super().__init__(f"closed with {code} {reason}".strip())
        self.code = code
        self.reason = reason


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters of one Link since it started (`dropped` and `queued` are the outbox's)."""

    sent: int
    acked: int
    replayed: int
    dropped: int
    reconnects: int
    queued: int
    rtcm_sent: int
    rtcm_dropped: int
    rtcm_received: int
    bad_inbound: int
    commands_executed: int
    commands_redelivered: int
    telemetry_queued: int = 0  # telemetry samples handed to the outbox since the link started
    events_queued: int = 0


@dataclass
class LinkCore:
    """What a link shares with its successive connections."""

    outbox: AsyncOutbox
    dispatcher: CommandDispatcher
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    acked: asyncio.Event = field(default_factory=asyncio.Event)
    connected: asyncio.Event = field(default_factory=asyncio.Event)
    counts: Counter[str] = field(default_factory=Counter)
    rtcm_callback: RtcmCallback | None = None
    ws: ClientConnection | None = None
    bucket: TokenBucket | None = None
    sessions: int = 0


class Conversation:
    """One connection's exchange with the server, from hello to close."""

    def __init__(
        self,
        core: LinkCore,
        ws: ClientConnection,
        hello: HelloPayload,
        *,
        heartbeat_s: float | None,
        welcome_timeout: float,
        batch: int,
        window: int,
        max_rate: float,
        burst: float,
    ):
        """Talk over `ws`; `heartbeat_s` None means the interval the server's welcome names.

        Sends are paced to `max_rate` per second (bursts of `burst`): the server rejects,
        and never stores, what exceeds its per-socket rate limit.
        """
        self.core = core
        self.ws = ws
        self.hello = hello
        self.heartbeat_s = heartbeat_s
        self.welcome_timeout = welcome_timeout
        self.batch = batch
        self.window = window
        self.bucket = TokenBucket(max_rate, burst)
        self.acked_seq = 0  # applied to the outbox
        self.ack_target = 0  # highest ack received, applied by the acker
        self.sent_seq = 0
        self.replay_mark = 0
        self._ack_wake = asyncio.Event()

    async def run(self, *alongside: Coroutine[Any, Any, None]) -> None:
        """Open the session, then serve until the connection (or one of `alongside`) ends."""
        try:
            await self._run(alongside)
        except ConnectionClosed as err:
            close = err.rcvd
            raise LinkClosed(close.code if close else 1006, close.reason if close else "") from err
        finally:
            for coro in alongside:
                coro.close()  # never started when the session did not open
            self.core.connected.clear()
            self.core.ws = None
            self.core.bucket = None

    async def _run(self, alongside: tuple[Coroutine[Any, Any, None], ...]) -> None:
        core, ws = self.core, self.ws
        await ws.send(encode(envelope(self.hello)))
        welcome = await asyncio.wait_for(self._welcome(), self.welcome_timeout)
        last = welcome.payload.last_acked_seq
        confirmed, backlog = await core.outbox.resume(last)
        core.counts["acked"] += confirmed
        self.acked_seq = self.ack_target = self.sent_seq = last
        self.replay_mark = await core.outbox.last_pos()
        reported = await core.outbox.report_drops()
        if reported:
            log.warning("reporting %d dropped messages to the server", reported)
        log.info("welcomed: the server has seq %d; %d queued to send", last, backlog)
        core.ws = ws
        core.bucket = self.bucket
        core.sessions += 1
        core.connected.set()
        core.wake.set()
        heartbeat = self.heartbeat_s or welcome.payload.heartbeat_s
        tasks = [
            asyncio.create_task(self._sender()),
            asyncio.create_task(self._receiver()),
            asyncio.create_task(self._acker()),
            asyncio.create_task(self._heartbeat(heartbeat)),
            *(asyncio.create_task(coro) for coro in alongside),
        ]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                task.result()
            raise LinkClosed(ws.close_code or 1006, ws.close_reason or "")
        finally:
            await cancel_and_wait(tasks)

    async def _welcome(self) -> Welcome:
        while True:
            msg = decode(await self.ws.recv(), "server_to_asset")
            if isinstance(msg, Welcome):
                return msg
            if isinstance(msg, Error):
                raise LinkClosed(1008, f"server error before welcome: {msg.payload.code}")
            log.warning("ignoring %s before welcome", getattr(msg, "type", msg))

    async def _sender(self) -> None:
        core = self.core
        while True:
            room = self.window - (self.sent_seq - self.acked_seq)
            if room <= 0:
                core.acked.clear()
                await core.acked.wait()
                continue
            core.wake.clear()
            pending = await core.outbox.take(min(self.batch, room))
            if not pending:
                await core.wake.wait()
                continue
            for entry in pending:
                # Before the send: its ack may be handled while the send still drains.
                await self.bucket.acquire()
                self.sent_seq = entry.seq
                await self.ws.send(entry.text)
                core.counts["sent"] += 1
                if entry.pos <= self.replay_mark:
                    core.counts["replayed"] += 1

    async def _receiver(self) -> None:
        async for text in self.ws:
            msg = decode(text, "server_to_asset")
            try:
                await self._dispatch(msg)
            except ConnectionClosed:
                raise
            except Exception:
                log.exception("handling an inbound %s failed", getattr(msg, "type", "message"))

    async def _dispatch(self, msg: Any) -> None:
        core = self.core
        if isinstance(msg, DecodeError):
            core.counts["bad"] += 1
            log.warning("bad message from the server: %s: %s", msg.code, msg.message)
            await self.bucket.acquire()
            await self.ws.send(encode(envelope(msg.to_payload())))
        elif isinstance(msg, Ack):
            seq = min(msg.payload.seq, self.sent_seq)
            if seq > self.ack_target:
                self.ack_target = seq
                self._ack_wake.set()
        elif isinstance(msg, Command):
            await core.dispatcher.handle(msg)
        elif isinstance(msg, Rtcm):
            core.counts["rtcm_received"] += 1
            if core.rtcm_callback is not None:
                outcome = core.rtcm_callback(msg.payload.frame)
                if inspect.isawaitable(outcome):
                    await outcome
        elif isinstance(msg, Error):
            log.warning("server error %s: %s", msg.payload.code, msg.payload.message)
            if msg.payload.code == "rate_limited":
                self.bucket.slow_down()
                log.warning("slowing down to %.0f messages/s", self.bucket.rate)
        else:
            log.warning("ignoring unexpected %s", msg.type)

    async def _acker(self) -> None:
        """Apply acks to the outbox, coalescing those that arrive while one is applied."""
        while True:
            await self._ack_wake.wait()
            self._ack_wake.clear()
            target = self.ack_target
            if target > self.acked_seq:
                self.core.counts["acked"] += await self.core.outbox.ack(target)
                self.acked_seq = target
                self.core.acked.set()

    async def _heartbeat(self, interval: float) -> None:
        while True:
            await asyncio.sleep(interval)
            pong = await self.ws.ping()
            try:
                await asyncio.wait_for(pong, interval)
            except TimeoutError:
                log.warning("no pong within %.1f s: the link is dead", interval)
                await self.ws.close(1011, "keepalive ping timeout")
                return
