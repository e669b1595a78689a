"""Camera sources as aiortc tracks: the newest frame at the configured size and rate.

The sender encodes each frame once (VP8; aiortc's encoder follows the viewer path's REMB between
250 kb/s and 1.5 Mb/s and answers PLI with a keyframe). A source that delivers faster than the
configured rate is thinned; one that stalls repeats nothing (the track waits).
"""

from __future__ import annotations

import asyncio
import fractions
import logging
import time
from collections.abc import AsyncIterator, Callable

import av
import cv2
import numpy as np
from aiortc.mediastreams import MediaStreamError, MediaStreamTrack

from asset_agent.precland.transport import TransportError, stream_frames
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

CLOCK_RATE = 90000
TIME_BASE = fractions.Fraction(1, CLOCK_RATE)

Images = Callable[[], AsyncIterator[np.ndarray]]
"""A factory of BGR images (a fresh iterator per call: the source reconnects by calling it again)."""


class CameraTrack(MediaStreamTrack):
    """A video track of BGR images resized to width×height, at most `fps` per second."""

    kind = "video"

    def __init__(self, images: Images, width: int, height: int, fps: float) -> None:
        super().__init__()
        self.width, self.height, self.fps = width, height, fps
        self._images = images
        self._newest: asyncio.Queue[np.ndarray] = asyncio.Queue(maxsize=1)
        self._start = time.monotonic()
        self._last_pts = -1
        self._next_due = 0.0
        self.frames = 0
        self._reader = asyncio.ensure_future(self._read())

    async def _read(self) -> None:
        while True:
            try:
                async for image in self._images():
                    if self._newest.full():
                        self._newest.get_nowait()  # keep only the newest
                    self._newest.put_nowait(image)
            except (OSError, ValueError, TransportError) as err:
                log.warning("camera source failed: %s; retrying", err)
            await asyncio.sleep(1.0)

    async def recv(self) -> av.VideoFrame:
        """The next frame, no sooner than 1/fps after the previous one."""
        if self.readyState != "live":
            raise MediaStreamError
        delay = self._next_due - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        image = await self._newest.get()
        now = time.monotonic()
        self._next_due = max(self._next_due + 1.0 / self.fps, now)
        if image.shape[1] != self.width or image.shape[0] != self.height:
            image = cv2.resize(image, (self.width, self.height), interpolation=cv2.INTER_AREA)
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        pts = max(int((now - self._start) * CLOCK_RATE), self._last_pts + 1)
        self._last_pts = pts
        frame.pts = pts
        frame.time_base = TIME_BASE
        self.frames += 1
        return frame

    def stop(self) -> None:
        """Stop reading the source."""
        self._reader.cancel()
        super().stop()

    async def aclose(self) -> None:
        """Stop and wait for the reader to end."""
        self.stop()
        await cancel_and_wait([self._reader])


def sim_camera(host: str, port: int) -> Images:
    """Images from the simulated downward camera (sim/camera/server.py's TCP stream)."""

    async def images() -> AsyncIterator[np.ndarray]:
        async for frame in stream_frames(host, port):
            yield frame.image

    return images


def video_file(path: str) -> Images:
    """Images from a video file, looped, paced at the file's own rate by the track."""

    async def images() -> AsyncIterator[np.ndarray]:
        while True:
            container = await asyncio.to_thread(av.open, path)
            try:
                decoded = container.decode(video=0)
                while True:
                    frame = await asyncio.to_thread(next, decoded, None)
                    if frame is None:
                        break
                    yield frame.to_ndarray(format="bgr24")
            finally:
                container.close()

    return images
