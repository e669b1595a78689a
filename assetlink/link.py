"""The resilient link of a daemon to the server: session, WebSocket, outbox, commands.

`Link` logs in with the asset's name and secret, keeps its token (persisted next to the outbox so a
restarted daemon resumes its session instead of being refused with 409), renews it before expiry,
connects to `/ws/asset`, and reconnects with exponential backoff and full jitter. Each connection
is a `Conversation`: hello, welcome with the server's last acked seq, replay of the outbox past it,
then live traffic with heartbeats. Durable messages (telemetry, events, command results) go through
the on-disk outbox and carry seq >= 1; RTCM frames, hello and error replies are sent only while
connected, seq 0.
"""

from __future__ import annotations

import asyncio
import logging
import random
import time
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import httpx
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

from assetlink import auth
from assetlink.conversation import (
    Conversation,
    LinkClosed,
    LinkCore,
    LinkStats,
    RtcmCallback,
    SessionEnded,
)
from assetlink.dispatch import CommandDispatcher, Handler
from assetlink.outbox import AsyncOutbox, Token
from assetlink.settings import LinkSettings, backoff_delay
from asynckit.tasks import cancel_and_wait
from protocol.base import MAX_MESSAGE_BYTES
from protocol.codec import encode
from protocol.messages import AgentKind, EventPayload, HelloPayload, RtcmPayload, envelope, now_ms
from protocol.telemetry_payloads import LandingBaseTelemetry, UavTelemetry

__all__ = ["Link", "LinkClosed", "LinkStats", "SessionEnded", "backoff_delay", "renew_at", "ws_url"]

log = logging.getLogger(__name__)

# Close codes after which the token is no longer usable: log in again.
TOKEN_DEAD_CODES = frozenset({4001, 4401})
_ENVELOPE_OVERHEAD = 400
DAEMON_KEY = "daemon:"  # the daemon's own key/values (recall, remember), apart from the link's


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
        settings: LinkSettings | None = None,
        *,
        agent: AgentKind = "asset_agent",
        seed: int | None = None,
    ):
        """Configure the link of asset `name` (a daemon of kind `agent`); nothing happens
        before `start()`. `seed` fixes the backoff's jitter (tests)."""
        self.server_url = server_url
        self.name = name
        self._secret = secret
        self.state_path = Path(state_path)
        self.agent: AgentKind = agent
        self.settings = settings or LinkSettings()
        self._rng = random.Random(seed)
        self._core: LinkCore | None = None
        self._http: httpx.AsyncClient | None = None
        self._session: auth.SessionClient | None = None
        self._handlers: dict[str, Handler] = {}
        self._rtcm_callback: RtcmCallback | None = None
        self._token: Token | None = None
        self._task: asyncio.Task[None] | None = None

    # --- public API ---

    def on_command(self, name: str, handler: Handler) -> None:
        """Run `handler` for inbound commands called `name` (see assetlink.dispatch)."""
        self._handlers[name] = handler
        if self._core is not None:
            self._core.dispatcher.register(name, handler)

    def on_rtcm(self, callback: RtcmCallback) -> None:
        """Call `callback(frame)` (sync or async) for every inbound RTCM3 frame."""
        self._rtcm_callback = callback
        if self._core is not None:
            self._core.rtcm_callback = callback

    @property
    def token(self) -> str | None:
        """The session's bearer token, for the asset's other calls to the server (video's WHIP);
        None before the first login."""
        return self._token.access_token if self._token is not None else None

    @property
    def connected(self) -> bool:
        """True between the server's welcome and the end of that connection."""
        return self._core is not None and self._core.connected.is_set()

    @property
    def stream_id(self) -> str:
        """This link's durable stream id (after start)."""
        return str(self._require_core().outbox.sync.stream_id)

    @property
    def stats(self) -> LinkStats:
        """A snapshot of the counters."""
        core = self._require_core()
        c, outbox, commands = core.counts, core.outbox.sync, core.dispatcher.stats
        return LinkStats(
            sent=c["sent"],
            acked=c["acked"],
            replayed=c["replayed"],
            dropped=outbox.dropped_total(),
            reconnects=max(0, core.sessions - 1),
            queued=len(outbox),
            rtcm_sent=c["rtcm_sent"],
            rtcm_dropped=c["rtcm_dropped"],
            rtcm_received=c["rtcm_received"],
            bad_inbound=c["bad"],
            commands_executed=commands.executed,
            commands_redelivered=commands.redelivered,
            telemetry_queued=c["queued_telemetry"],
            events_queued=c["queued_event"],
        )

    async def start(self) -> None:
        """Open the state file and start connecting in the background."""
        if self._task is not None:
            raise RuntimeError("link already started")
        self.state_path.parent.mkdir(parents=True, exist_ok=True)
        outbox = await AsyncOutbox.open(self.state_path, self.settings.max_outbox)
        dispatcher = CommandDispatcher(outbox)
        core = LinkCore(outbox, dispatcher, rtcm_callback=self._rtcm_callback)
        dispatcher.queued = core.wake.set
        for name, handler in self._handlers.items():
            dispatcher.register(name, handler)
        self._core = core
        self._token = await self._restore_token()
        await outbox.prune_commands(now_ms() - int(self.settings.command_memory_s * 1000))
        await dispatcher.recover()
        self._http = httpx.AsyncClient(timeout=self.settings.connect_timeout)
        self._session = auth.SessionClient(self.server_url, self.name, self._secret, self._http)
        self._task = asyncio.create_task(self._run(), name=f"link-{self.name}")

    async def stop(self, *, logout: bool = False) -> None:
        """Cancel running commands, close the connection and the state file.

        The session is kept for the next start unless `logout` is set.
        """
        core = self._core
        if core is None:
            return
        await core.dispatcher.stop()
        await cancel_and_wait([self._task])
        self._task = None
        if logout and self._token is not None and self._session is not None:
            try:
                await self._session.logout(self._token.access_token)
            except auth.AuthError as err:
                log.warning("logout failed: %s", err)
            await self._set_token(None)
        if self._http is not None:
            await self._http.aclose()
        await core.outbox.close()
        self._core = None

    async def wait_connected(self, timeout: float | None = None) -> None:  # noqa: ASYNC109
        """Wait until the server has welcomed this link; TimeoutError past `timeout`."""
        async with asyncio.timeout(timeout):
            await self._require_core().connected.wait()

    async def flush(self, timeout: float) -> bool:  # noqa: ASYNC109
        """Wait until the server has acked what was queued before the call; False at the timeout."""
        core = self._require_core()
        try:
            async with asyncio.timeout(timeout):
                target = await core.outbox.last_pos()
                core.acked.clear()
                while 0 < await core.outbox.first_pos() <= target:
                    await core.acked.wait()
                    core.acked.clear()
        except TimeoutError:
            return False
        return True

    async def recall(self, key: str) -> str | None:
        """A value kept with `remember`, in this run or an earlier one; None if none."""
        return await self._require_core().outbox.meta(DAEMON_KEY + key)  # type: ignore[no-any-return]

    async def remember(self, key: str, value: str | None) -> None:
        """Keep a value of the daemon's own in the state file, committed when this returns, for
        the daemon started after a crash (None: forget it)."""
        await self._require_core().outbox.set_meta(DAEMON_KEY + key, value)

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
        core = self._require_core()
        ws, bucket = core.ws, core.bucket
        if ws is None or bucket is None or not core.connected.is_set():
            core.counts["rtcm_dropped"] += 1
            return False
        try:
            await bucket.acquire()
            await ws.send(encode(envelope(RtcmPayload.from_frame(frame))))
        except ConnectionClosed:
            core.counts["rtcm_dropped"] += 1
            return False
        core.counts["rtcm_sent"] += 1
        return True

    # --- internals ---

    def _require_core(self) -> LinkCore:
        if self._core is None:
            raise RuntimeError("link not started")
        return self._core

    async def _queue(self, kind: str, payload: str) -> None:
        core = self._require_core()
        if len(payload) + _ENVELOPE_OVERHEAD > MAX_MESSAGE_BYTES:
            raise ValueError(f"{kind} payload of {len(payload)} bytes exceeds the message limit")
        dropped = await core.outbox.append(kind, payload)
        core.counts[f"queued_{kind}"] += 1
        if dropped:
            log.warning(
                "outbox full (%d): dropped the %d oldest", self.settings.max_outbox, dropped
            )
        core.wake.set()

    async def _restore_token(self) -> Token | None:
        """The persisted token, unless it was issued for another server or asset name."""
        outbox = self._require_core().outbox
        identity = f"{self.server_url.rstrip('/')}|{self.name}"
        if await outbox.call(outbox.sync.meta, "identity") != identity:
            await outbox.save_token(None)
            await outbox.call(outbox.sync.set_meta, "identity", identity)
            return None
        return await outbox.load_token()

    async def _set_token(self, token: Token | None) -> None:
        self._token = token
        if self._core is not None:
            await self._core.outbox.save_token(token)

    async def _run(self) -> None:
        attempt = 0
        while True:
            floor = 0.0
            sessions_before = self._require_core().sessions
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
            except auth.AuthError as err:  # unreachable, or a 503's Retry-After: as long as it asks
                log.warning("session call failed: %s", err)
                floor = err.retry_after
            except LinkClosed as err:
                log.info("link closed: %s", err)
                if err.code in TOKEN_DEAD_CODES:
                    await self._set_token(None)
            except (OSError, InvalidHandshake, TimeoutError) as err:
                log.info("cannot connect: %s: %s", type(err).__name__, err)
            except Exception:
                log.exception("link session failed")
            if self._require_core().sessions > sessions_before:
                attempt = 0
            delay = backoff_delay(
                attempt, self.settings.backoff_min, self.settings.backoff_max, self._rng
            )
            attempt += 1
            await asyncio.sleep(max(floor, delay))

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
        fresh = await self._session.login(force=self.settings.force_login)
        await self._set_token(fresh)
        return fresh

    async def _connection(self, token: Token) -> None:
        core = self._require_core()
        try:
            ws = await connect(
                ws_url(self.server_url),
                additional_headers={"Authorization": f"Bearer {token.access_token}"},
                max_size=MAX_MESSAGE_BYTES,
                ping_interval=None,
                open_timeout=self.settings.connect_timeout,
                close_timeout=2,
            )
        except InvalidStatus as err:
            status = err.response.status_code
            if status in (401, 403):
                raise SessionEnded(f"WebSocket refused the token ({status})") from err
            raise LinkClosed(4409 if status == 409 else 1006, f"handshake {status}") from err
        hello = HelloPayload(
            stream=core.outbox.sync.stream_id, agent=self.agent, version=self.settings.version
        )
        traffic = self.settings.traffic
        conversation = Conversation(
            core,
            ws,
            hello,
            heartbeat_s=traffic.heartbeat_s,
            welcome_timeout=self.settings.connect_timeout,
            batch=traffic.batch,
            window=traffic.window,
            max_rate=traffic.max_rate,
            burst=traffic.burst,
        )
        try:
            await conversation.run(self._renewer())
        finally:
            await ws.close()

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
