"""Client side of the sensor transports: camera frames over TCP, IR-beacon readings over UDP.

Camera (see the simulated camera's server for why TCP): every frame is a 28-byte little-endian
header then the payload::

    struct "<4sBBHIdHHI": magic b"ABCF", version 1, encoding (0 raw BGR8, 1 JPEG), reserved,
                          seq (uint32), capture_ts (float64 s, world clock), width, height,
                          payload length (uint32)

IR sensor: one 28-byte datagram per reading::

    struct "<4sBBHIdff": magic b"ABIR", version 1, flags (bit 0: detected), reserved,
                         seq (uint32), capture_ts (float64 s), angle_x, angle_y (float32 rad)

angle_x / angle_y are the beacon's direction in camera axes: atan2(x, z), atan2(y, z) with x right
and y towards the tail. Malformed input is logged and dropped, never raised into the caller's loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from collections.abc import AsyncIterator
from dataclasses import dataclass

import cv2
import numpy as np

log = logging.getLogger(__name__)

FRAME_HEADER = struct.Struct("<4sBBHIdHHI")
FRAME_MAGIC = b"ABCF"
IR_DATAGRAM = struct.Struct("<4sBBHIdff")
IR_MAGIC = b"ABIR"
MAX_PAYLOAD = 16 * 1024 * 1024


class TransportError(Exception):
    """A sensor stream sent something that is not in its documented format."""


@dataclass(frozen=True)
class Frame:
    """One camera frame: BGR image and the time it was captured (world clock, seconds)."""

    seq: int
    capture_ts: float
    image: np.ndarray


@dataclass(frozen=True)
class IrReading:
    """One IR-beacon reading."""

    seq: int
    capture_ts: float
    detected: bool
    angle_x: float
    angle_y: float


def parse_frame_header(data: bytes) -> tuple[int, float, int, int, int, int]:
    """(seq, capture_ts, width, height, encoding, length) from a header; raises TransportError."""
    magic, version, enc, _, seq, ts, w, h, length = FRAME_HEADER.unpack(data)
    if magic != FRAME_MAGIC or version != 1 or enc not in (0, 1) or length > MAX_PAYLOAD:
        raise TransportError(f"bad frame header {data!r}")
    if enc == 0 and length != w * h * 3:
        raise TransportError(f"raw frame of {w}x{h} with {length} bytes")
    return seq, ts, w, h, enc, length


def decode_image(width: int, height: int, encoding: int, payload: bytes) -> np.ndarray:
    """The BGR image of a payload; raises TransportError."""
    if encoding == 0:
        return np.frombuffer(payload, dtype=np.uint8).reshape(height, width, 3)
    img = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise TransportError("undecodable JPEG frame")
    return img


async def stream_frames(host: str, port: int) -> AsyncIterator[Frame]:
    """Frames from the camera server until it closes; JPEG decoding runs in a worker thread."""
    reader, writer = await asyncio.open_connection(host, port)
    try:
        while True:
            try:
                head = await reader.readexactly(FRAME_HEADER.size)
            except asyncio.IncompleteReadError:
                return
            seq, ts, w, h, enc, length = parse_frame_header(head)
            payload = await reader.readexactly(length)
            if enc == 0:
                image = decode_image(w, h, enc, payload)
            else:
                image = await asyncio.to_thread(decode_image, w, h, enc, payload)
            yield Frame(seq, ts, image)
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


def parse_ir(datagram: bytes) -> IrReading | None:
    """The reading in one datagram, or None (logged) when it is malformed."""
    if len(datagram) != IR_DATAGRAM.size:
        log.warning("IR datagram of %d bytes dropped", len(datagram))
        return None
    magic, version, flags, _, seq, ts, ax, ay = IR_DATAGRAM.unpack(datagram)
    if magic != IR_MAGIC or version != 1:
        log.warning("IR datagram with bad magic/version dropped")
        return None
    return IrReading(seq, ts, bool(flags & 1), ax, ay)


class IrReceiver(asyncio.DatagramProtocol):
    """Binds a UDP port and queues the IR readings it receives (bounded; oldest dropped)."""

    def __init__(self, maxsize: int = 64) -> None:
        self.queue: asyncio.Queue[IrReading] = asyncio.Queue(maxsize)
        self.dropped = 0
        self._transport: asyncio.DatagramTransport | None = None

    async def start(self, host: str = "127.0.0.1", port: int = 0) -> int:
        """Bind; returns the bound port."""
        loop = asyncio.get_running_loop()
        self._transport, _ = await loop.create_datagram_endpoint(
            lambda: self, local_addr=(host, port)
        )
        return self._transport.get_extra_info("sockname")[1]

    def subscribe(self, host: str, port: int) -> None:
        """Ask a sensor that serves subscribers (the simulated one) to send readings here."""
        assert self._transport is not None, "start() first"
        self._transport.sendto(IR_MAGIC, (host, port))

    def datagram_received(self, data: bytes, addr) -> None:
        """Queue a well-formed reading."""
        reading = parse_ir(data)
        if reading is None:
            self.dropped += 1
            return
        if self.queue.full():
            self.queue.get_nowait()
        self.queue.put_nowait(reading)

    async def readings(self) -> AsyncIterator[IrReading]:
        """Readings as they arrive."""
        while True:
            yield await self.queue.get()

    def close(self) -> None:
        """Release the socket."""
        if self._transport:
            self._transport.close()


async def frames_forever(host: str, port: int, retry_s: float = 1.0) -> AsyncIterator[Frame]:
    """Frames from the camera, reconnecting (after `retry_s`) when the stream ends, breaks or
    sends something malformed — logged, never raised."""
    while True:
        try:
            async for frame in stream_frames(host, port):
                yield frame
            log.warning("camera stream %s:%d ended; reconnecting", host, port)
        except (OSError, TransportError, asyncio.IncompleteReadError) as err:
            log.warning("camera stream %s:%d failed (%s); reconnecting", host, port, err)
        await asyncio.sleep(retry_s)
