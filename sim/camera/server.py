"""Serves the simulated camera's frames, with capture timestamps, over TCP on localhost.

Transport: one TCP connection per subscriber; every frame is a 28-byte little-endian header
followed by the payload::

    struct "<4sBBHIdHHI": magic b"ABCF", version 1, encoding (0 raw BGR8, 1 JPEG), reserved 0,
                          seq (uint32), capture_ts (float64 seconds on the world's clock),
                          width, height (uint16), payload length (uint32)

Why TCP with raw frames: it is reliable, ordered and framed by our header, so a frame is never torn
(UDP would need fragmentation above 64 KiB); raw BGR keeps the exact colours and edges the
detector measures (JPEG blurs 6-pixel red points at 6 m); 640x480x3 at 30 FPS is 27 MB/s, nothing
for loopback; and unlike shared memory it needs no locking protocol, works across containers and
is what a network camera on the companion computer would give. A slow subscriber never builds a
backlog: each connection holds only the newest unsent frame (older ones are dropped), which is
what a landing controller wants. The server only renders while someone is subscribed.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from asynckit.tasks import cancel_and_wait
from sim.camera.render import PadRenderer, Pose

log = logging.getLogger(__name__)

HEADER = struct.Struct("<4sBBHIdHHI")
MAGIC = b"ABCF"
VERSION = 1
ENCODING_RAW_BGR8 = 0
ENCODING_JPEG = 1


@dataclass(frozen=True)
class FrameHeader:
    """The header that precedes every frame on the wire."""

    seq: int
    capture_ts: float
    width: int
    height: int
    encoding: int
    length: int


def encode_frame(seq: int, capture_ts: float, image: np.ndarray, jpeg_quality: int = 0) -> bytes:
    """Header + payload for one BGR frame (JPEG when jpeg_quality > 0, raw otherwise)."""
    h, w = image.shape[:2]
    if jpeg_quality > 0:
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        if not ok:
            raise ValueError("JPEG encoding failed")
        payload, enc = buf.tobytes(), ENCODING_JPEG
    else:
        payload, enc = np.ascontiguousarray(image).tobytes(), ENCODING_RAW_BGR8
    return (
        HEADER.pack(MAGIC, VERSION, enc, 0, seq & 0xFFFFFFFF, capture_ts, w, h, len(payload))
        + payload
    )


class _Clock(Protocol):
    """The part of sim.clock.SimClock the server needs."""

    def now(self) -> float:
        """Simulated seconds."""
        ...

    async def sleep(self, sim_seconds: float) -> None:
        """Sleep in simulated seconds."""
        ...


class CameraServer:
    """Renders frames at `fps` (simulated time) from `pose_fn()` and streams them to subscribers."""

    def __init__(
        self,
        pose_fn: Callable[[], Pose],
        clock: _Clock,
        renderer: PadRenderer | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        fps: float = 30.0,
        jpeg_quality: int = 0,
    ) -> None:
        self.pose_fn = pose_fn
        self.clock = clock
        self.renderer = renderer or PadRenderer()
        self.host, self.port = host, port
        self.fps = fps
        self.jpeg_quality = jpeg_quality
        self.frames_sent = 0
        self.stamp_offset = 0.0  # capture timestamps are the clock's seconds less this
        self._server: asyncio.Server | None = None
        self._slots: set[_Slot] = set()
        self._task: asyncio.Task | None = None
        self._seq = 0
        self._subscribed = asyncio.Event()  # the capture loop sleeps while nobody watches

    async def start(self) -> int:
        """Bind and start capturing; returns the bound TCP port."""
        self._server = await asyncio.start_server(self._serve, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        self._task = asyncio.create_task(self._capture_loop(), name="camera-capture")
        log.info("camera serving on %s:%d at %.0f FPS", self.host, self.port, self.fps)
        return self.port

    def restart_stamps(self, at: float = 0.0) -> None:
        """Capture timestamps count from `at` again (the camera rebooted, or the world restarted
        under a running agent); the capture schedule runs on."""
        self.stamp_offset = self.clock.now() - at

    async def stop(self) -> None:
        """Stop capturing and close every connection (closing a writer does not wake a handler
        waiting for its next frame: each is cancelled, or it would outlive the loop pending)."""
        await cancel_and_wait([self._task, *(slot.task for slot in self._slots)])
        if self._server:
            self._server.close()
            await self._server.wait_closed()

    async def _capture_loop(self) -> None:
        period = 1.0 / self.fps
        next_t = self.clock.now()
        while True:
            next_t += period
            await self.clock.sleep(next_t - self.clock.now())
            if self.clock.now() - next_t > period:  # fell behind: skip, never burst
                next_t = self.clock.now()
            if not self._slots:
                await self._subscribed.wait()
                next_t = self.clock.now()
                continue
            try:
                pose = self.pose_fn()
                ts = self.clock.now() - self.stamp_offset
                image = await asyncio.to_thread(self.renderer.render, pose)
                data = await asyncio.to_thread(
                    encode_frame, self._seq, ts, image, self.jpeg_quality
                )
            except Exception:
                log.exception("camera capture failed; skipping a frame")
                continue
            self._seq += 1
            for slot in list(self._slots):
                slot.offer(data)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None  # start_server runs each connection as a task
        slot = _Slot(task)
        self._slots.add(slot)
        self._subscribed.set()
        log.info("camera subscriber %s", writer.get_extra_info("peername"))
        try:
            while True:
                data = await slot.take()
                writer.write(data)
                await writer.drain()
                self.frames_sent += 1
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self._slots.discard(slot)
            if not self._slots:
                self._subscribed.clear()
            writer.close()


class _Slot:
    """Holds the newest unsent frame for one subscriber, served by `task`."""

    def __init__(self, task: asyncio.Task) -> None:
        self.task = task
        self._data: bytes | None = None
        self._ready = asyncio.Event()

    def offer(self, data: bytes) -> None:
        """Replace the waiting frame with a newer one."""
        self._data = data
        self._ready.set()

    async def take(self) -> bytes:
        """Wait for a frame and take it."""
        await self._ready.wait()
        self._ready.clear()
        data, self._data = self._data, None
        assert data is not None
        return data
