"""RTK corrections in: RTCM3 over TCP or a serial port, for both daemons: the base reads its GNSS
receiver; the agent reads the base's local stream (base_station/rtcm_server.py) on the site's
network, so corrections reach the UAV with the server down (asset_agent/corrections.py).

The byte stream is reframed and CRC-checked (`protocol.rtcm.Reframer`); good frames go to an
async callback and to any number of async-iterator subscribers; bad frames, skipped bytes,
the corrections rate and the age of the last good frame are tracked; a lost source is
reconnected with exponential backoff. Serial reads happen in a worker thread.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import Counter, deque
from collections.abc import AsyncGenerator, Awaitable, Callable
from dataclasses import dataclass, field
from typing import Protocol
from urllib.parse import parse_qs, urlsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator

from asynckit.tasks import cancel_and_wait
from protocol.rtcm import Reframer, message_type
from protocol.telemetry_payloads import Rtk

log = logging.getLogger(__name__)

FrameCallback = Callable[[bytes], Awaitable[object]]


@dataclass(frozen=True)
class TcpSource:
    """RTCM3 from a TCP server (a receiver's or an NTRIP-less stream port)."""

    host: str
    port: int


@dataclass(frozen=True)
class SerialSource:
    """RTCM3 from a serial device."""

    device: str
    baud: int = 115200


def parse_source(url: str) -> TcpSource | SerialSource:
    """Parse `tcp://host:port` or `serial:///dev/ttyUSB0?baud=115200`."""
    parts = urlsplit(url)
    if parts.scheme == "tcp":
        if not parts.hostname or parts.port is None:
            raise ValueError(f"tcp source needs host and port: {url!r}")
        return TcpSource(parts.hostname, parts.port)
    if parts.scheme == "serial":
        device = (parts.netloc + parts.path) if parts.netloc else parts.path
        if not device:
            raise ValueError(f"serial source needs a device path: {url!r}")
        baud = parse_qs(parts.query).get("baud", ["115200"])[0]
        return SerialSource(device, int(baud))
    raise ValueError(f"unsupported RTCM source {url!r} (use tcp:// or serial://)")


def source_url(
    tcp_host: str = "127.0.0.1",
    tcp_port: int = 5021,
    serial_device: str = "",
    baudrate: int = 115200,
) -> str:
    """A source URL from host/port/device settings (a serial device wins when set)."""
    if serial_device:
        return f"serial://{serial_device}?baud={baudrate}"
    return f"tcp://{tcp_host}:{tcp_port}"


class RtkConfig(BaseModel):
    """Where the corrections come from and how the reader behaves."""

    model_config = ConfigDict(frozen=True)

    source: str = "tcp://127.0.0.1:5021"
    rate_window_s: float = Field(default=10.0, gt=0)
    reconnect_min_s: float = Field(default=0.5, gt=0)
    reconnect_max_s: float = Field(default=10.0, gt=0)
    subscriber_queue: int = Field(default=256, ge=1)
    connect_timeout_s: float = Field(default=5.0, gt=0)
    idle_reconnect_s: float | None = Field(
        default=30.0, gt=0, description="reconnect when the source sends nothing for this long"
    )

    @field_validator("source")
    @classmethod
    def _valid_source(cls, value: str) -> str:
        parse_source(value)
        return value


@dataclass
class Backoff:
    """Exponential reconnect delay: doubles per failure up to a cap, resets after a success."""

    minimum: float
    maximum: float
    _next: float = 0.0

    def failure(self) -> float:
        """The delay to wait after a failed or lost connection."""
        self._next = self.minimum if self._next == 0.0 else min(self.maximum, self._next * 2)
        return self._next

    def success(self) -> None:
        """A connection delivered data: start from the minimum next time."""
        self._next = 0.0


@dataclass
class RateMeter:
    """Frames/s and bytes/s over a sliding window of `window_s` seconds."""

    window_s: float
    _events: deque[tuple[float, int]] = field(default_factory=deque)
    _bytes: int = 0

    def add(self, now: float, nbytes: int) -> None:
        """Record one frame of `nbytes` seen at `now`."""
        self._events.append((now, nbytes))
        self._bytes += nbytes
        self._trim(now)

    def rates(self, now: float) -> tuple[float, float]:
        """(frames per second, bytes per second) over the window ending at `now`."""
        self._trim(now)
        return len(self._events) / self.window_s, self._bytes / self.window_s

    def _trim(self, now: float) -> None:
        while self._events and self._events[0][0] <= now - self.window_s:
            _, n = self._events.popleft()
            self._bytes -= n


@dataclass(frozen=True)
class RtkStats:
    """A snapshot of the corrections link."""

    source: str
    connected: bool
    connects: int
    good_frames: int
    bad_frames: int
    bytes_received: int
    good_bytes: int
    skipped_bytes: int
    dropped_frames: int
    frames_per_s: float
    bytes_per_s: float
    last_frame_age_s: float | None
    message_counts: dict[int, int]


def rtk_state(stats: RtkStats, stale_after_s: float = 5.0) -> str:
    """`disconnected`, `waiting` (connected, nothing yet), `stale` (no frame lately) or `streaming`."""
    if not stats.connected:
        return "disconnected"
    if stats.last_frame_age_s is None:
        return "waiting"
    return "stale" if stats.last_frame_age_s > stale_after_s else "streaming"


def to_telemetry(stats: RtkStats, stale_after_s: float = 5.0) -> Rtk:
    """The landing-base telemetry block for the corrections link (rate in frames per second)."""
    return Rtk(
        state=rtk_state(stats, stale_after_s),
        corrections_rate=stats.frames_per_s,
        correction_age_s=stats.last_frame_age_s,
        frames_total=stats.good_frames,
        bad_frames=stats.bad_frames,
    )


class _Link(Protocol):
    async def read(self) -> bytes: ...

    async def close(self) -> None: ...


class _TcpLink:
    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._reader, self._writer = reader, writer

    @classmethod
    async def open(cls, src: TcpSource) -> _TcpLink:
        reader, writer = await asyncio.open_connection(src.host, src.port)
        return cls(reader, writer)

    async def read(self) -> bytes:
        return await self._reader.read(65536)

    async def close(self) -> None:
        self._writer.close()
        with contextlib.suppress(OSError, ConnectionError):
            await self._writer.wait_closed()


class _SerialLink:
    """pyserial behind a thread boundary: every blocking call runs in a worker thread."""

    POLL_S = 0.2

    def __init__(self, port: object) -> None:
        self._port = port

    @classmethod
    async def open(cls, src: SerialSource) -> _SerialLink:
        try:
            import serial  # pyserial: only serial sources need it
        except ImportError as err:
            raise ConnectionError(
                "serial sources need pyserial (pip install 'pyserial>=3.5')"
            ) from err

        def _open() -> object:
            return serial.Serial(src.device, src.baud, timeout=cls.POLL_S)

        try:
            return cls(await asyncio.to_thread(_open))
        except (serial.SerialException, OSError) as err:
            raise ConnectionError(f"cannot open {src.device}: {err}") from err

    def _read_blocking(self) -> bytes | None:
        import serial

        port = self._port
        try:
            first = port.read(1)  # type: ignore[attr-defined]
            if not first:
                return None  # poll timeout: nothing yet
            return first + port.read(port.in_waiting)  # type: ignore[attr-defined]
        except (serial.SerialException, OSError) as err:
            raise ConnectionError(str(err)) from err

    async def read(self) -> bytes:
        while True:
            data = await asyncio.to_thread(self._read_blocking)
            if data is not None:
                return data

    async def close(self) -> None:
        await asyncio.to_thread(self._port.close)  # type: ignore[attr-defined]


class RtkReader:
    """Reads, checks and hands out RTCM3 frames from the configured source, reconnecting forever."""

    def __init__(
        self,
        config: RtkConfig,
        on_frame: FrameCallback | None = None,
        *,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.source = parse_source(config.source)
        self._on_frame = on_frame
        self._now = monotonic
        self._meter = RateMeter(config.rate_window_s)
        self._backoff = Backoff(config.reconnect_min_s, config.reconnect_max_s)
        self._subscribers: set[asyncio.Queue[bytes]] = set()
        self._types: Counter[int] = Counter()
        self._connected = False
        self._connects = 0
        self._good = self._bad = self._skipped = 0
        self._bytes = self._good_bytes = self._dropped = 0
        self._last_good: float | None = None
        self._task: asyncio.Task[None] | None = None
        self.connected_event = asyncio.Event()

    def stats(self) -> RtkStats:
        """The current counters, rates and age of the last good frame."""
        now = self._now()
        fps, bps = self._meter.rates(now)
        return RtkStats(
            source=self.config.source,
            connected=self._connected,
            connects=self._connects,
            good_frames=self._good,
            bad_frames=self._bad,
            bytes_received=self._bytes,
            good_bytes=self._good_bytes,
            skipped_bytes=self._skipped,
            dropped_frames=self._dropped,
            frames_per_s=fps,
            bytes_per_s=bps,
            last_frame_age_s=None if self._last_good is None else now - self._last_good,
            message_counts=dict(self._types),
        )

    async def frames(self) -> AsyncGenerator[bytes, None]:
        """Every good frame from now on (a slow consumer loses the oldest, counted as dropped)."""
        queue: asyncio.Queue[bytes] = asyncio.Queue(self.config.subscriber_queue)
        self._subscribers.add(queue)
        try:
            while True:
                yield await queue.get()
        finally:
            self._subscribers.discard(queue)

    def start(self) -> None:
        """Run the reader as a background task."""
        if self._task is None:
            self._task = asyncio.create_task(self.run(), name="rtk-reader")

    async def stop(self) -> None:
        """Stop the background task started by `start`."""
        await cancel_and_wait([self._task])
        self._task = None

    async def run(self) -> None:
        """Connect, read and reconnect with backoff until cancelled."""
        while True:
            try:
                link = await self._open()
            except (OSError, ConnectionError) as err:
                delay = self._backoff.failure()
                log.warning(
                    "rtk source %s unavailable (%s); retrying in %.1fs",
                    self.config.source,
                    str(err) or type(err).__name__,
                    delay,
                )
                await asyncio.sleep(delay)
                continue
            self._connects += 1
            self._connected = True
            self.connected_event.set()
            log.info("rtk source %s connected", self.config.source)
            try:
                await self._pump(link)
                reason = "closed by the source"
            except (OSError, ConnectionError) as err:
                reason = str(err) or type(err).__name__
            finally:
                self._connected = False
                self.connected_event.clear()
                await link.close()
            delay = self._backoff.failure()
            log.warning(
                "rtk source %s lost (%s); reconnecting in %.1fs", self.config.source, reason, delay
            )
            await asyncio.sleep(delay)

    async def _open(self) -> _Link:
        async with asyncio.timeout(self.config.connect_timeout_s):
            if isinstance(self.source, TcpSource):
                return await _TcpLink.open(self.source)
            return await _SerialLink.open(self.source)

    async def _read(self, link: _Link) -> bytes:
        try:
            async with asyncio.timeout(self.config.idle_reconnect_s):
                return await link.read()
        except TimeoutError as err:
            raise ConnectionError(f"no data for {self.config.idle_reconnect_s:g}s") from err

    async def _pump(self, link: _Link) -> None:
        reframer = Reframer()  # a new connection starts a new byte stream
        while data := await self._read(link):
            self._bytes += len(data)
            frames = list(reframer.feed(data))
            self._bad += reframer.bad_frames
            self._skipped += reframer.skipped_bytes
            reframer.bad_frames = reframer.skipped_bytes = 0
            for frame in frames:
                await self._deliver(frame)

    async def _deliver(self, frame: bytes) -> None:
        now = self._now()
        self._good += 1
        self._good_bytes += len(frame)
        self._last_good = now
        self._meter.add(now, len(frame))
        self._backoff.success()
        mtype = message_type(frame)
        if mtype is not None:
            self._types[mtype] += 1
        for queue in self._subscribers:
            if queue.full():
                queue.get_nowait()
                self._dropped += 1
            queue.put_nowait(frame)
        if self._on_frame is not None:
            try:
                await self._on_frame(frame)
            except Exception:
                log.exception("rtk frame callback failed; frame dropped")
