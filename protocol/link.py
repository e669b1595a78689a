"""The resilient link of a daemon to the server: session, WebSocket, outbox, commands.

`Link` logs in with the asset's name and secret, keeps its token (persisted next to the
outbox so a restarted daemon resumes its session), connects to `/ws/asset`, says hello,
replays the outbox past the server's last ack, then sends live; it reconnects with
exponential backoff and full jitter, pings to detect a dead link, renews its token before
expiry, acks-driven deletes from the outbox, runs inbound commands once per id and hands
inbound RTCM frames to a callback.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import random
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import httpx
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

from protocol import auth
from protocol.base import MAX_MESSAGE_BYTES
from protocol.codec import DecodeError, decode, encode
from protocol.commands import CommandDispatcher, Handler
from protocol.messages import (
    Ack,
    AgentKind,
    Command,
    Error,
    EventPayload,
    HelloPayload,
    Rtcm,
    RtcmPayload,
    Welcome,
    envelope,
)
from protocol.outbox import AsyncOutbox, Token
from protocol.telemetry import LandingBaseTelemetry, UavTelemetry

log = logging.getLogger(__name__)

RtcmCallback = Callable[[bytes], Awaitable[None] | None]
# Close codes after which the token is no longer usable: log in again.
TOKEN_DEAD_CODES = frozenset({4001, 4401})
_ENVELOPE_OVERHEAD = 400


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters of one Link since it started."""

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


class SessionEnded(Exception):
    """The server ended the session (or refused the token): log in again."""


class LinkClosed(Exception):
    """The WebSocket closed; `code` is its close code (1006 when none was received)."""

    def __init__(self, code: int, reason: str = ""):
        """Keep the close code and reason."""
        super().__init__(f"closed with {code} {reason}".strip())
        self.code = code
        self.reason = reason


def backoff_delay(attempt: int, low: float, high: float, rng: random.Random) -> float:
    """Exponential backoff with full jitter: uniform in [0, min(high, low * 2**attempt)]."""
    cap = min(high, low * (2 ** min(attempt, 62)))
    return rng.uniform(0, cap)


def ws_url(server_url: str, path: str = "/ws/asset") -> str:
    """The WebSocket URL of `path` on an http(s) server URL."""
    parts = urlsplit(server_url)
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    return urlunsplit((scheme, parts.netloc, parts.path.rstrip("/") + path, "", ""))


def renew_at(token: Token, now: float, fraction: float = 0.75) -> float:
    """When to renew a token: after `fraction` of its remaining life."""
    return now + max(0.0, token.expires_at - now) * fraction


class Link:
    """A daemon's connection to the server, which loses no durable message."""

    def __init__(
        self,
        server_url: str,
        name: str,
        secret: str,
        state_path: str | Path,
        *,
        agent: AgentKind = "asset_agent",
        version: str = "0.1.0",
        max_outbox: int = 100_000,
        backoff_min: float = 0.5,
        backoff_max: float = 30.0,
        heartbeat_s: float | None = None,
        connect_timeout: float = 10.0,
        batch: int = 256,
        window: int = 4096,
        force_login: bool = False,
        seed: int | None = None,
    ):
        """Configure the link; nothing happens before `start()`.

        `heartbeat_s` overrides the server's ping interval (a pong missing for that long
        closes the link); `window` bounds messages sent and not yet acked.
        """
        self.server_url = server_url
        self.name = name
        self._secret = secret
        self.state_path = Path(state_path)
        self.agent: AgentKind = agent
        self.version = version
        self.max_outbox = max_outbox
        self.backoff_min = backoff_min
        self.backoff_max = backoff_max
        self.heartbeat_s = heartbeat_s
        self.connect_timeout = connect_timeout
        self.batch = batch
        self.window = window
        self.force_login = force_login
        self._rng = random.Random(seed)
        self._outbox: AsyncOutbox | None = None
        self._http: httpx.AsyncClient | None = None
        self._session: auth.SessionClient | None = None
        self._dispatcher: CommandDispatcher | None = None
        self._pending_handlers: dict[str, Handler] = {}
        self._rtcm_callback: RtcmCallback | None = None
        self._token: Token | None = None
        self._ws: ClientConnection | None = None
        self._task: asyncio.Task[None] | None = None
        self._connected = asyncio.Event()
        self._wake = asyncio.Event()
        self._acked_event = asyncio.Event()
        self._acked_seq = 0
        self._sent_seq = 0
        self._replay_mark = 0
        self._sessions = 0
        self._counts = dict.fromkeys(
            ("sent", "acked", "replayed", "rtcm_sent", "rtcm_dropped", "rtcm_received", "bad"), 0
        )

    # --- public API ---

    def on_command(self, name: str, handler: Handler) -> None:
        """Run `handler` for inbound commands called `name`."""
        if self._dispatcher is not None:
            self._dispatcher.register(name, handler)
        self._pending_handlers[name] = handler

    def on_rtcm(self, callback: RtcmCallback) -> None:
        """Call `callback(frame)` (sync or async) for every inbound RTCM3 frame."""
        self._rtcm_callback = callback

    @property
    def connected(self) -> bool:
        """True between the server's welcome and the end of that connection."""
        return self._connected.is_set()

    @property
    def stream_id(self) -> str:
        """This link's durable stream id (after start)."""
        return str(self._require_outbox().sync.stream_id)

    @property
    def stats(self) -> LinkStats:
        """A snapshot of the counters."""
        outbox = self._outbox.sync if self._outbox else None
        commands = self._dispatcher.stats if self._dispatcher else None
        c = self._counts
        return LinkStats(
            sent=c["sent"],
            acked=c["acked"],
            replayed=c["replayed"],
            dropped=outbox.dropped_total() if outbox else 0,
            reconnects=max(0, self._sessions - 1),
            queued=len(outbox) if outbox else 0,
            rtcm_sent=c["rtcm_sent"],
            rtcm_dropped=c["rtcm_dropped"],
            rtcm_received=c["rtcm_received"],
            bad_inbound=c["bad"],
            commands_executed=commands.executed if commands else 0,
            commands_redelivered=commands.redelivered if commands else 0,
        )

    async def start(self) -> None:
        """Open the state file and start connecting in the background."""
        if self._task is not None:
            raise RuntimeError("link already started")
        self.state_path.parent.mkdir(parents=True, exist_ok=True)
        self._outbox = await AsyncOutbox.open(self.state_path, self.max_outbox)
        self._token = await self._outbox.load_token()
        self._http = httpx.AsyncClient(timeout=self.connect_timeout)
        self._session = auth.SessionClient(self.server_url, self.name, self._secret, self._http)
        self._dispatcher = CommandDispatcher(self._outbox, self._wake.set)
        for name, handler in self._pending_handlers.items():
            self._dispatcher.register(name, handler)
        await self._dispatcher.recover()
        self._task = asyncio.create_task(self._run(), name=f"link-{self.name}")

    async def stop(self, *, logout: bool = False) -> None:
        """Cancel running commands, close the connection and the state file.

        The session is kept for the next start unless `logout` is set.
        """
        if self._dispatcher is not None:
            await self._dispatcher.stop()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if logout and self._token is not None and self._session is not None:
            try:
                await self._session.logout(self._token.access_token)
            except auth.AuthError as err:
                log.warning("logout failed: %s", err)
            await self._set_token(None)
        if self._http is not None:
            await self._http.aclose()
        if self._outbox is not None:
            await self._outbox.close()
            self._outbox = None

    async def wait_connected(self, timeout: float | None = None) -> None:  # noqa: ASYNC109
        """Wait until the server has welcomed this link; TimeoutError past `timeout`."""
        async with asyncio.timeout(timeout):
            await self._connected.wait()

    async def flush(self, timeout: float) -> bool:  # noqa: ASYNC109
        """Wait until the server has acked everything queued; False at the timeout."""
        outbox = self._require_outbox()
        try:
            async with asyncio.timeout(timeout):
                while len(outbox.sync) > 0:
                    self._acked_event.clear()
                    if len(outbox.sync) == 0:
                        break
                    await self._acked_event.wait()
        except TimeoutError:
            return False
        return True

    async def send_telemetry(self, payload: UavTelemetry | LandingBaseTelemetry) -> None:
        """Queue one telemetry sample (durable: sent, replayed if needed, acked)."""
        if not isinstance(payload, UavTelemetry | LandingBaseTelemetry):
            raise TypeError(f"telemetry must be a telemetry model, not {type(payload).__name__}")
        await self._queue("telemetry", payload.model_dump_json())

    async def send_event(self, payload: EventPayload) -> None:
        """Queue one event (durable)."""
        if not isinstance(payload, EventPayload):
            raise TypeError(f"an event must be an EventPayload, not {type(payload).__name__}")
        await self._queue("event", payload.model_dump_json())

    async def send_rtcm(self, frame: bytes) -> bool:
        """Send one RTCM3 frame now if connected (corrections are not queued); False if not."""
        ws = self._ws
        if ws is None or not self.connected:
            self._counts["rtcm_dropped"] += 1
            return False
        text = encode(envelope(RtcmPayload.from_frame(frame)))
        try:
            await ws.send(text)
        except ConnectionClosed:
            self._counts["rtcm_dropped"] += 1
            return False
        self._counts["rtcm_sent"] += 1
        return True

    # --- internals ---

    def _require_outbox(self) -> AsyncOutbox:
        if self._outbox is None:
            raise RuntimeError("link not started")
        return self._outbox

    async def _queue(self, kind: str, payload: str) -> None:
        if len(payload) + _ENVELOPE_OVERHEAD > MAX_MESSAGE_BYTES:
            raise ValueError(f"{kind} payload of {len(payload)} bytes exceeds the message limit")
        dropped = await self._require_outbox().append(kind, payload)
        if dropped:
            log.warning("outbox full (%d): dropped the %d oldest", self.max_outbox, dropped)
        self._wake.set()

    async def _set_token(self, token: Token | None) -> None:
        self._token = token
        if self._outbox is not None:
            await self._outbox.save_token(token)

    async def _run(self) -> None:
        attempt = 0
        while True:
            floor = 0.0
            welcomed_before = self._sessions
            try:
                token = await self._ensure_token()
                await self._connection(token)
            except asyncio.CancelledError:
                raise
            except auth.RateLimited as err:
                log.warning("rate limited: retrying after %.1f s", err.retry_after)
                floor = err.retry_after
            except auth.SessionActive:
                log.warning("asset %r has another live session: backing off", self.name)
            except auth.BadCredentials as err:
                log.error("%s", err)
            except (auth.SessionGone, SessionEnded) as err:
                log.info("session ended (%s): logging in again", err)
                await self._set_token(None)
            except auth.AuthError as err:
                log.warning("session call failed: %s", err)
            except LinkClosed as err:
                log.info("link closed: %s", err)
                if err.code in TOKEN_DEAD_CODES:
                    await self._set_token(None)
            except (OSError, InvalidHandshake, TimeoutError) as err:
                log.info("cannot connect: %s: %s", type(err).__name__, err)
            except Exception:
                log.exception("link session failed")
            if self._sessions > welcomed_before:
                attempt = 0
            delay = max(
                floor, backoff_delay(attempt, self.backoff_min, self.backoff_max, self._rng)
            )
            attempt += 1
            await asyncio.sleep(delay)

    async def _ensure_token(self) -> Token:
        assert self._session is not None
        token, now = self._token, time.time()
        if token is not None and renew_at(token, now) > now + 1:
            return token
        if token is not None and token.expires_at > now + 1:
            try:
                fresh = await self._session.renew(token.access_token)
            except auth.SessionGone:
                await self._set_token(None)
            else:
                await self._set_token(fresh)
                return fresh
        fresh = await self._session.login(force=self.force_login)
        await self._set_token(fresh)
        return fresh

    async def _connection(self, token: Token) -> None:
        headers = {"Authorization": f"Bearer {token.access_token}"}
        try:
            ws = await connect(
                ws_url(self.server_url),
                additional_headers=headers,
                max_size=MAX_MESSAGE_BYTES,
                ping_interval=None,
                open_timeout=self.connect_timeout,
                close_timeout=2,
            )
        except InvalidStatus as err:
            status = err.response.status_code
            if status in (401, 403):
                raise SessionEnded(f"WebSocket refused the token ({status})") from err
            raise LinkClosed(4409 if status == 409 else 1006, f"handshake {status}") from err
        try:
            await self._converse(ws)
        except ConnectionClosed as err:
            close = err.rcvd
            raise LinkClosed(close.code if close else 1006, close.reason if close else "") from err
        finally:
            self._connected.clear()
            self._ws = None
            await ws.close()

    async def _converse(self, ws: ClientConnection) -> None:
        outbox = self._require_outbox()
        hello = HelloPayload(stream=outbox.sync.stream_id, agent=self.agent, version=self.version)
        await ws.send(encode(envelope(hello)))
        welcome = await asyncio.wait_for(self._welcome(ws), self.connect_timeout)
        last = welcome.payload.last_acked_seq
        confirmed, backlog = await outbox.resume(last)
        self._counts["acked"] += confirmed
        self._acked_seq = self._sent_seq = last
        self._replay_mark = await outbox.last_pos()
        reported = await outbox.report_drops()
        if reported:
            log.warning("reported %d dropped messages to the server", reported)
        log.info("connected as %r: server has seq %d, replaying %d", self.name, last, backlog)
        self._ws = ws
        self._sessions += 1
        self._connected.set()
        self._wake.set()
        heartbeat = self.heartbeat_s or welcome.payload.heartbeat_s
        tasks = [
            asyncio.create_task(self._sender(ws)),
            asyncio.create_task(self._receiver(ws)),
            asyncio.create_task(self._heartbeat(ws, heartbeat)),
            asyncio.create_task(self._renewer()),
        ]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                task.result()
            raise LinkClosed(ws.close_code or 1006, ws.close_reason or "")
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    async def _welcome(self, ws: ClientConnection) -> Welcome:
        while True:
            msg = decode(await ws.recv(), "server_to_asset")
            if isinstance(msg, Welcome):
                return msg
            if isinstance(msg, Error):
                raise LinkClosed(1008, f"server error before welcome: {msg.payload.code}")
            log.warning("ignoring %s before welcome", getattr(msg, "type", msg))

    async def _sender(self, ws: ClientConnection) -> None:
        outbox = self._require_outbox()
        while True:
            room = self.window - (self._sent_seq - self._acked_seq)
            if room <= 0:
                self._acked_event.clear()
                await self._acked_event.wait()
                continue
            self._wake.clear()
            pending = await outbox.take(min(self.batch, room))
            if not pending:
                await self._wake.wait()
                continue
            for entry in pending:
                # Before the send: its ack may be handled while the send still drains.
                self._sent_seq = entry.seq
                await ws.send(entry.text)
                self._counts["sent"] += 1
                if entry.pos <= self._replay_mark:
                    self._counts["replayed"] += 1

    async def _receiver(self, ws: ClientConnection) -> None:
        async for text in ws:
            msg = decode(text, "server_to_asset")
            try:
                await self._dispatch(ws, msg)
            except ConnectionClosed:
                raise
            except Exception:
                log.exception("handling an inbound %s failed", getattr(msg, "type", "message"))

    async def _dispatch(self, ws: ClientConnection, msg: Any) -> None:
        if isinstance(msg, DecodeError):
            self._counts["bad"] += 1
            log.warning("bad message from the server: %s: %s", msg.code, msg.message)
            await ws.send(encode(envelope(msg.to_payload())))
        elif isinstance(msg, Ack):
            seq = min(msg.payload.seq, self._sent_seq)
            if seq > self._acked_seq:
                self._counts["acked"] += await self._require_outbox().ack(seq)
                self._acked_seq = seq
            self._acked_event.set()
        elif isinstance(msg, Command):
            assert self._dispatcher is not None
            await self._dispatcher.handle(msg)
        elif isinstance(msg, Rtcm):
            self._counts["rtcm_received"] += 1
            if self._rtcm_callback is not None:
                outcome = self._rtcm_callback(msg.payload.frame)
                if inspect.isawaitable(outcome):
                    await outcome
        elif isinstance(msg, Error):
            log.warning("server error %s: %s", msg.payload.code, msg.payload.message)
        else:
            log.warning("ignoring unexpected %s", msg.type)

    async def _heartbeat(self, ws: ClientConnection, interval: float) -> None:
        while True:
            await asyncio.sleep(interval)
            pong = await ws.ping()
            try:
                await asyncio.wait_for(pong, interval)
            except TimeoutError:
                log.warning("no pong within %.1f s: the link is dead", interval)
                await ws.close(1011, "keepalive ping timeout")
                return

    async def _renewer(self) -> None:
        assert self._session is not None
        while True:
            token = self._token
            if token is None:
                raise SessionEnded("token forgotten")
            now = time.time()
            await asyncio.sleep(max(0.0, renew_at(token, now) - now))
            try:
                fresh = await self._session.renew(token.access_token)
            except auth.SessionGone as err:
                raise SessionEnded(str(err)) from err
            except auth.AuthError as err:
                if time.time() >= token.expires_at:
                    raise SessionEnded("the token expired before it could be renewed") from err
                log.warning("renewing the token failed (%s): retrying", err)
                await asyncio.sleep(min(5.0, max(0.5, token.expires_at - time.time()) / 4))
                continue
            await self._set_token(fresh)
            log.info("token renewed")
