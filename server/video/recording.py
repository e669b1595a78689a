"""Recording an asset's stream to disk as it arrives, without decoding or re-encoding it.

The recorder listens to the relay's channel (`forward.Channel`) and muxes the forwarded VP8 frames
into WebM segments with PyAV on a worker thread: `<dir>/<asset id>/<UTC start>.webm`, a new
segment at the first keyframe after `segment_s`. Beside each segment, `<same>.times.jsonl` holds
one line per frame, `{"pts": <90 kHz>, "t": <unix ms when the server received it>}`: the
server's clock. Telemetry `ts` is the agent's clock (its envelope stamp), so a frame is placed on
a run's timeline up to the clocks' offset and the capture-to-server latency (~50-100 ms on a good
link): frontend_api.md, "Frame times and telemetry times are two clocks". Retention
deletes the oldest segments beyond `max_age_s` or `max_bytes`.
"""

from __future__ import annotations

import asyncio
import contextlib
import fractions
import json
import logging
import queue
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import av

from server.video.forward import EncodedFrame

log = logging.getLogger(__name__)

TIME_BASE = fractions.Fraction(1, 90000)


def vp8_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a VP8 keyframe header (RFC 6386 §9.1), None for other frames."""
    if len(data) < 10 or data[0] & 0x01 or data[3:6] != b"\x9d\x01\x2a":
        return None
    return (
        int.from_bytes(data[6:8], "little") & 0x3FFF,
        int.from_bytes(data[8:10], "little") & 0x3FFF,
    )


@dataclass
class _Segment:
    path: Path
    container: av.container.OutputContainer
    stream: av.video.stream.VideoStream
    times: object  # the open .times.jsonl file
    first_pts: int
    started: float


class Recorder:
    """Records one asset's forwarded frames into segments (one worker thread per recording)."""

    def __init__(
        self,
        folder: Path,
        asset_id: uuid.UUID,
        segment_s: float,
        request_keyframe: Callable[[], None] = lambda: None,
    ) -> None:
        self.folder = folder / str(asset_id)
        self.segment_s = segment_s
        self._request_keyframe = request_keyframe
        self._cut_at: float | None = None  # when the current segment started (event loop side)
        self._queue: queue.Queue[tuple[EncodedFrame, float, bool] | None] = queue.Queue(maxsize=600)
        self._thread = threading.Thread(target=self._run, name=f"record-{asset_id}", daemon=True)
        self._segment: _Segment | None = None
        self.frames = 0
        self.dropped = 0
        self._thread.start()

    def offer(self, frame: EncodedFrame) -> None:
        """A forwarded frame (event loop): queued for the writer, dropped if the disk lags.

        A segment is due every segment_s; it starts at a keyframe, asked of the publisher when due
        (its encoder makes one only on request)."""
        now = time.time()
        due = self._cut_at is None or now - self._cut_at >= self.segment_s
        cut = due and frame.keyframe
        if cut:
            self._cut_at = now
        elif due:
            self._request_keyframe()
        try:
            self._queue.put_nowait((frame, now, cut))
        except queue.Full:
            self.dropped += 1

    def close(self) -> None:
        """Finish the current segment and stop the writer (blocks until it has)."""
        self._queue.put(None)
        self._thread.join(30)

    def _run(self) -> None:
        try:
            while (item := self._queue.get()) is not None:
                frame, at, cut = item
                try:
                    self._write(frame, at, cut)
                except (OSError, av.FFmpegError, ValueError) as err:
                    log.error("recording failed, segment closed: %s", err)
                    self._finish()
        finally:
            self._finish()

    def _write(self, frame: EncodedFrame, at: float, cut: bool) -> None:
        segment = self._segment
        if cut:
            self._finish()
            segment = self._start(frame, at)
        if segment is None:
            return  # wait for a keyframe: a segment must start decodable
        packet = av.Packet(frame.data)
        packet.stream = segment.stream
        pts = (frame.timestamp - segment.first_pts) & 0xFFFFFFFF
        packet.pts = packet.dts = pts
        packet.time_base = TIME_BASE
        packet.is_keyframe = frame.keyframe
        segment.container.mux(packet)  # rescales the packet to WebM's milliseconds, in place
        segment.times.write(json.dumps({"pts": pts, "t": round(at * 1000)}) + "\n")  # type: ignore[attr-defined]
        self.frames += 1

    def _start(self, frame: EncodedFrame, at: float) -> _Segment | None:
        size = vp8_size(frame.data)
        if size is None:
            return None
        self.folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.fromtimestamp(at, UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        path = self.folder / f"{stamp}.webm"
        container = av.open(str(path), "w", format="webm")
        stream = container.add_stream("libvpx")
        stream.width, stream.height = size
        stream.pix_fmt = "yuv420p"
        stream.time_base = TIME_BASE
        times = open(path.with_suffix(".times.jsonl"), "w", buffering=1)  # whole lines, at once
        self._segment = _Segment(path, container, stream, times, frame.timestamp, at)
        return self._segment

    def _finish(self) -> None:
        segment, self._segment = self._segment, None
        if segment is None:
            return
        with contextlib.suppress(OSError, av.FFmpegError):
            segment.container.close()
        with contextlib.suppress(OSError):
            segment.times.close()  # type: ignore[attr-defined]


@dataclass(frozen=True)
class Recording:
    """Where and how the relay records (from the settings)."""

    folder: Path
    segment_s: float
    max_age_s: float
    max_bytes: int
    retention_every_s: float = 60.0

    async def retention_loop(self) -> None:
        """Apply the retention now and then, off the event loop, until cancelled."""
        while True:
            try:
                deleted = await asyncio.to_thread(
                    apply_retention, self.folder, self.max_age_s, self.max_bytes
                )
                if deleted:
                    log.info("recording retention deleted %d segment(s)", deleted)
            except OSError as err:
                log.warning("recording retention failed: %s", err)
            await asyncio.sleep(self.retention_every_s)


def apply_retention(
    folder: Path, max_age_s: float, max_bytes: int, now: float | None = None
) -> int:
    """Delete segments older than max_age_s, then the oldest until the rest fit max_bytes.

    Returns how many segments were deleted. A segment and its times file go together."""
    now = now if now is not None else time.time()
    segments = sorted(folder.glob("*/*.webm"), key=lambda p: p.stat().st_mtime)
    sizes = {p: p.stat().st_size for p in segments}
    total = sum(sizes.values())
    deleted = 0
    for path in segments:
        too_old = now - path.stat().st_mtime > max_age_s
        if not too_old and total <= max_bytes:
            continue
        total -= sizes[path]
        with contextlib.suppress(OSError):
            path.unlink()
            path.with_suffix(".times.jsonl").unlink(missing_ok=True)
            deleted += 1
    return deleted
