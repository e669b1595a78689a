"""Publish/subscribe and presence between server processes: in-process (default) or Redis.

Channels carry JSON-able dicts. Presence (`claim`) is a key with an owner and a time to live, so
one asset has one live connection across any number of processes.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from typing import Any, Protocol

from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

Handler = Callable[[dict[str, Any]], None]


class Broker(Protocol):
    """What the hub needs from a broker."""

    async def start(self) -> None:
        """Connect."""

    async def close(self) -> None:
        """Disconnect."""

    async def ping(self) -> None:
        """Return when the broker answers; raise when it cannot be reached."""

    async def publish(self, channel: str, message: dict[str, Any]) -> None:
        """Send to every subscriber of `channel`, in every process."""

    def publish_nowait(self, channel: str, message: dict[str, Any]) -> None:
        """`publish` without waiting (the hot path): in order with every other `publish_nowait`
        of this process; never blocks, never raises."""

    def subscribe(self, channel: str, handler: Handler) -> None:
        """Call `handler` (in the event loop, must not block) for each message on `channel`."""

    def unsubscribe(self, channel: str, handler: Handler) -> None:
        """Stop calling `handler` for `channel`."""

    async def claim(self, key: str, owner: str, ttl_s: float) -> str | None:
        """Take `key` for `owner` unless someone else holds it; returns the holder, None when ours."""

    async def refresh(self, key: str, owner: str, ttl_s: float) -> bool:
        """Extend our claim; False when we no longer hold it."""

    async def refresh_many(self, claims: list[tuple[str, str]], ttl_s: float) -> list[bool]:
        """`refresh` of many (key, owner) claims at once (one round trip to Redis)."""

    async def release(self, key: str, owner: str) -> None:
        """Give up our claim."""


class _Subscribers:
    def __init__(self) -> None:
        # a tuple per channel, replaced on (un)subscribe: a dispatch iterates it as it was, even
        # when a handler unsubscribes meanwhile, without copying it per message
        self.handlers: dict[str, tuple[Handler, ...]] = {}

    def add(self, channel: str, handler: Handler) -> bool:
        now = self.handlers.get(channel, ())
        self.handlers[channel] = (*now, handler)
        return not now

    def remove(self, channel: str, handler: Handler) -> bool:
        now = list(self.handlers.get(channel, ()))
        with contextlib.suppress(ValueError):
            now.remove(handler)
        if not now:
            self.handlers.pop(channel, None)
            return True
        self.handlers[channel] = tuple(now)
        return False

    def dispatch(self, channel: str, message: dict[str, Any]) -> None:
        for handler in self.handlers.get(channel, ()):
            try:
                handler(message)
            except Exception:
                log.exception("broker handler failed on %s", channel)


class InProcessBroker:
    """A broker for one server process."""

    def __init__(self) -> None:
        self._subs = _Subscribers()
        self._claims: dict[str, tuple[str, float]] = {}

    async def start(self) -> None:
        """Nothing to connect."""

    async def close(self) -> None:
        """Nothing to disconnect."""

    async def ping(self) -> None:
        """Always reachable: it lives in this process."""

    async def publish(self, channel: str, message: dict[str, Any]) -> None:
        """Deliver in this process."""
        self._subs.dispatch(channel, message)

    def publish_nowait(self, channel: str, message: dict[str, Any]) -> None:
        """Deliver in this process, now."""
        self._subs.dispatch(channel, message)

    def subscribe(self, channel: str, handler: Handler) -> None:
        """Register a handler."""
        self._subs.add(channel, handler)

    def unsubscribe(self, channel: str, handler: Handler) -> None:
        """Remove a handler."""
        self._subs.remove(channel, handler)

    async def claim(self, key: str, owner: str, ttl_s: float) -> str | None:
        """Take the key unless another live owner holds it."""
        now = time.monotonic()
        holder = self._claims.get(key)
        if holder and holder[0] != owner and holder[1] > now:
            return holder[0]
        self._claims[key] = (owner, now + ttl_s)
        return None

    async def refresh(self, key: str, owner: str, ttl_s: float) -> bool:
        """Extend our claim."""
        holder = self._claims.get(key)
        if not holder or holder[0] != owner:
            return False
        self._claims[key] = (owner, time.monotonic() + ttl_s)
        return True

    async def refresh_many(self, claims: list[tuple[str, str]], ttl_s: float) -> list[bool]:
        """Extend each claim."""
        return [await self.refresh(key, owner, ttl_s) for key, owner in claims]

    async def release(self, key: str, owner: str) -> None:
        """Drop our claim."""
        if self._claims.get(key, ("",))[0] == owner:
            del self._claims[key]


_RELEASE = "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('del', KEYS[1]) else return 0 end"
_REFRESH = (
    "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('pexpire', KEYS[1], ARGV[2]) "
    "else return 0 end"
)


POOL_SIZE = 64  # connections to Redis per process (one is the subscription's)
POOL_WAIT_S = 10.0  # a caller waits this long for a free connection, then the call fails
OUTBOX_LIMIT = 100_000  # publish_nowait messages waiting for Redis; later ones are dropped


class RedisBroker:
    """A broker shared by every server process through Redis pub/sub and keys."""

    def __init__(self, url: str, prefix: str = "aerobase:") -> None:
        self.url = url
        self.prefix = prefix
        self._subs = _Subscribers()
        self._redis: Any = None
        self._pubsub: Any = None
        self._reader: asyncio.Task[None] | None = None
        self._outbox: deque[tuple[str, str]] = deque()  # publish_nowait, in order
        self._outbox_ready = asyncio.Event()
        self._publisher: asyncio.Task[None] | None = None
        self.dropped = 0  # publish_nowait messages dropped (Redis away past OUTBOX_LIMIT)

    async def start(self) -> None:
        """Connect and start the reader task."""
        import redis.asyncio as redis

        # a bounded pool that makes a caller wait for a free connection: the default pool raises
        # "Too many connections" past 100 at once, which 200 UAVs at 10 Hz reach (every asset
        # session publishes each message), and each refused publish failed its socket
        pool = redis.BlockingConnectionPool.from_url(
            self.url,
            decode_responses=True,
            max_connections=POOL_SIZE,
            timeout=POOL_WAIT_S,
        )
        self._redis = redis.Redis.from_pool(pool)
        await self._redis.ping()
        self._pubsub = self._redis.pubsub(ignore_subscribe_messages=True)
        await self._pubsub.subscribe(f"{self.prefix}__keepalive")
        self._reader = asyncio.create_task(self._read(), name="redis-broker")
        self._publisher = asyncio.create_task(self._publish_outbox(), name="redis-publisher")

    async def ping(self) -> None:
        """Redis PING over the broker's own connection pool."""
        if self._redis is None:
            raise ConnectionError("the Redis broker is not started")
        await self._redis.ping()

    async def close(self) -> None:
        """Stop the reader and the publisher (after what it holds, for at most a second), and
        disconnect."""
        await cancel_and_wait([self._reader, self._publisher])
        if self._outbox and self._redis is not None:
            batch = list(self._outbox)
            self._outbox.clear()
            try:
                await asyncio.wait_for(self._send(batch), 1.0)
            except Exception as err:
                log.warning("%d publications not sent at close: %r", len(batch), err)
        if self._pubsub:
            await self._pubsub.aclose()
        if self._redis:
            await self._redis.aclose()

    async def _read(self) -> None:
        while True:
            try:
                async for item in self._iter():
                    channel = item["channel"][len(self.prefix) :]
                    try:
                        message = json.loads(item["data"])
                    except ValueError:
                        continue
                    self._subs.dispatch(channel, message)
            except asyncio.CancelledError:
                raise
            except Exception:
                log.exception("redis subscription failed; retrying")
                await asyncio.sleep(0.5)

    async def _iter(self) -> AsyncIterator[dict[str, Any]]:
        async for item in self._pubsub.listen():
            if item.get("type") == "message":
                yield item

    async def publish(self, channel: str, message: dict[str, Any]) -> None:
        """Publish to every process."""
        await self._redis.publish(self.prefix + channel, json.dumps(message, separators=(",", ":")))

    def publish_nowait(self, channel: str, message: dict[str, Any]) -> None:
        """Queue for the publisher task, which sends what queued in one pipeline."""
        if len(self._outbox) >= OUTBOX_LIMIT:
            self.dropped += 1
            if self.dropped % 10_000 == 1:
                log.warning("Redis is not taking publications: %d dropped so far", self.dropped)
            return
        text = message.get("text")
        if isinstance(text, bytes):  # a frame's text, already UTF-8 (the hot path's telemetry)
            message = {**message, "text": text.decode()}
        self._outbox.append((self.prefix + channel, json.dumps(message, separators=(",", ":"))))
        self._outbox_ready.set()

    async def _publish_outbox(self) -> None:
        """Send queued publications in order, as many as are waiting in one round trip."""
        while True:
            await self._outbox_ready.wait()
            self._outbox_ready.clear()
            while self._outbox:
                batch = [self._outbox.popleft() for _ in range(min(len(self._outbox), 1000))]
                while True:
                    try:
                        await self._send(batch)
                        break
                    except asyncio.CancelledError:
                        raise
                    except Exception:
                        log.exception("publishing to Redis failed; retrying")
                        await asyncio.sleep(0.5)

    async def _send(self, batch: list[tuple[str, str]]) -> None:
        async with self._redis.pipeline(transaction=False) as pipe:
            for channel, data in batch:
                pipe.publish(channel, data)
            await pipe.execute()

    def subscribe(self, channel: str, handler: Handler) -> None:
        """Register a handler; the first one of a channel subscribes in Redis."""
        if self._subs.add(channel, handler):
            asyncio.get_running_loop().create_task(self._pubsub.subscribe(self.prefix + channel))

    def unsubscribe(self, channel: str, handler: Handler) -> None:
        """Remove a handler; the last one of a channel unsubscribes in Redis."""
        if self._subs.remove(channel, handler):
            asyncio.get_running_loop().create_task(self._pubsub.unsubscribe(self.prefix + channel))

    async def claim(self, key: str, owner: str, ttl_s: float) -> str | None:
        """SET NX PX; the current holder when taken."""
        full = self.prefix + key
        if await self._redis.set(full, owner, nx=True, px=int(ttl_s * 1000)):
            return None
        holder = await self._redis.get(full)
        if holder == owner:
            await self.refresh(key, owner, ttl_s)
            return None
        if holder is None:
            return await self.claim(key, owner, ttl_s)
        return str(holder)

    async def refresh(self, key: str, owner: str, ttl_s: float) -> bool:
        """Extend the TTL if we still hold the key."""
        return bool(
            await self._redis.eval(_REFRESH, 1, self.prefix + key, owner, int(ttl_s * 1000))
        )

    async def refresh_many(self, claims: list[tuple[str, str]], ttl_s: float) -> list[bool]:
        """Extend each claim we still hold: one pipeline for all."""
        if not claims:
            return []
        async with self._redis.pipeline(transaction=False) as pipe:
            for key, owner in claims:
                pipe.eval(_REFRESH, 1, self.prefix + key, owner, int(ttl_s * 1000))
            return [bool(held) for held in await pipe.execute()]

    async def release(self, key: str, owner: str) -> None:
        """Delete the key if we hold it."""
        await self._redis.eval(_RELEASE, 1, self.prefix + key, owner)


def make_broker(redis_url: str | None) -> Broker:
    """Redis when a URL is configured, else in-process."""
    return RedisBroker(redis_url) if redis_url else InProcessBroker()
