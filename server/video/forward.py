"""Forwarding encoded VP8 frames from one publisher to many viewers, never decoding them.

aiortc's public API always decodes what a peer receives (`RTCRtpReceiver` runs a decoder thread)
and always encodes what it sends from decoded frames, so a `MediaRelay` costs one decode per
asset plus one VP8 encode per viewer. Below that API:

- in: `RTCRtpReceiver._handle_rtp_packet` reassembles each frame in its jitter buffer and puts
  `(codec, JitterFrame)` on its decoder queue (`_RTCRtpReceiver__decoder_queue`, read at each
  put). `tap_receiver` replaces that queue with a `Tap` that hands the encoded frame to us and
  forwards only the stop sentinel to the idle decoder thread, so nothing is decoded; and the
  jitter buffer with one that releases a frame at its marked last packet (`jitter.py`), not when
  the next frame starts (one frame interval sooner).
- out: `RTCRtpSender` packetises an `av.Packet` a track returns (`Encoder.pack`) without encoding;
  `ForwardTrack` returns one packet per forwarded frame.

Keyframes: a viewer starts (and restarts after a dropped frame) at a keyframe; it asks the
publisher for one by RTCP PLI (`RTCRtpReceiver._send_rtcp_pli`, rate-limited). A viewer's own
PLI reaches its sender's `_send_keyframe`, which we point at the same request.
Pinned to aiortc 1.16 (pyproject); `tests/server/test_video_relay.py` fails if these hooks move.
"""

from __future__ import annotations

import asyncio
import logging
import queue
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import av
from aiortc.mediastreams import VIDEO_TIME_BASE, MediaStreamError, MediaStreamTrack

from server.kit.metrics import VIDEO_FRAMES
from server.video.jitter import JITTER_BUFFER, MarkerJitterBuffer

log = logging.getLogger(__name__)

DECODER_QUEUE = "_RTCRtpReceiver__decoder_queue"
QUEUE_FRAMES = 8  # a viewer further behind than this restarts at the next keyframe
KEYFRAME_REQUEST_INTERVAL_S = 0.5
RESTART_GAP = 3000  # 90 kHz ticks between the last frame of one publication and the next one's


@dataclass(frozen=True)
class EncodedFrame:
    """One VP8 frame as received: its bytes, its RTP timestamp (90 kHz) and whether it is a key."""

    data: bytes
    timestamp: int
    keyframe: bool


def is_vp8_keyframe(data: bytes) -> bool:
    """RFC 6386 §9.1: bit 0 of the frame tag is 0 for a key frame."""
    return bool(data) and not (data[0] & 0x01)


class Tap:
    """Stands in for a receiver's decoder queue: encoded frames go to `sink`, not the decoder."""

    def __init__(self, original: queue.Queue, sink: Callable[[bytes, int], None]) -> None:
        self.original = original
        self.sink = sink

    def put(self, item: Any) -> None:
        """Called by the receiver on the event loop with (codec, JitterFrame), or None to stop."""
        if item is None:
            self.original.put(None)  # the decoder thread ends and the receiver's track with it
            return
        _codec, frame = item
        self.sink(bytes(frame.data), int(frame.timestamp))

    def get(self) -> Any:
        """The decoder thread (started after the tap when the peer connects) waits here for the
        stop sentinel only."""
        return self.original.get()


def tap_receiver(receiver: Any, sink: Callable[[bytes, int], None], at_marker: bool = True) -> None:
    """Route a receiver's reassembled frames to `sink` instead of its decoder; with `at_marker`,
    reassemble each frame as soon as its last packet is in (`jitter.MarkerJitterBuffer`)."""
    original = getattr(receiver, DECODER_QUEUE, None)
    if not isinstance(original, queue.Queue) or not hasattr(receiver, JITTER_BUFFER):
        raise RuntimeError("aiortc's RTCRtpReceiver is not built as in 1.16 (decoder queue)")
    setattr(receiver, DECODER_QUEUE, Tap(original, sink))
    if at_marker:
        setattr(receiver, JITTER_BUFFER, MarkerJitterBuffer())


class ForwardTrack(MediaStreamTrack):
    """A viewer's track: the channel's encoded frames as `av.Packet`s, from a keyframe on."""

    kind = "video"

    def __init__(self, request_keyframe: Callable[[], None]) -> None:
        super().__init__()
        self._queue: asyncio.Queue[EncodedFrame | None] = asyncio.Queue()
        self._want_keyframe = True
        self._request_keyframe = request_keyframe
        self.frames_sent = 0

    def offer(self, frame: EncodedFrame) -> None:
        """Queue a frame for this viewer (called on the event loop)."""
        if self.readyState != "live":
            return
        if self._want_keyframe:
            if not frame.keyframe:
                self._request_keyframe()
                return
            self._want_keyframe = False
        if self._queue.qsize() >= QUEUE_FRAMES:
            # a slow viewer: drop what it has not sent; a delta frame needs its predecessor
            while not self._queue.empty():
                self._queue.get_nowait()
            self._want_keyframe = True
            self._request_keyframe()
            if not frame.keyframe:
                return
            self._want_keyframe = False
        self._queue.put_nowait(frame)

    async def recv(self) -> av.Packet:
        """The next frame, packed for the sender (which packetises it without encoding)."""
        if self.readyState != "live":
            raise MediaStreamError
        frame = await self._queue.get()
        if frame is None:
            raise MediaStreamError
        packet = av.Packet(frame.data)
        packet.pts = frame.timestamp
        packet.time_base = VIDEO_TIME_BASE
        self.frames_sent += 1
        return packet

    def stop(self) -> None:
        """End the track; the sender's loop ends on the sentinel."""
        if self.readyState == "live":
            self._queue.put_nowait(None)
        super().stop()


class Channel:
    """One asset's stream: the current publication's frames fanned out to its viewers.

    Viewers belong to the channel, not to a publication, so a publisher that reconnects (its
    link flapped) feeds the same viewers again; output timestamps stay monotonic across it.
    """

    def __init__(self) -> None:
        self.tracks: set[ForwardTrack] = set()
        self.listeners: list[Callable[[EncodedFrame], None]] = []  # recorders
        self._publication: object | None = None
        self._offset = 0
        self._last_out: int | None = None
        self._arrivals: deque[float] = deque(maxlen=64)
        self._keyframe_requester: Callable[[], None] | None = None
        self._last_request = 0.0

    def attach(self, publication: object, request_keyframe: Callable[[], None]) -> None:
        """A new publication feeds this channel from now on (replacing any previous one)."""
        self._publication = publication
        self._keyframe_requester = request_keyframe
        self._offset = -1  # set at the publication's first frame
        self._arrivals.clear()

    def detach(self, publication: object) -> None:
        """The publication ended (nothing happens if another has replaced it)."""
        if self._publication is publication:
            self._publication = None
            self._keyframe_requester = None
            self._arrivals.clear()

    @property
    def live(self) -> bool:
        """True while a publication feeds the channel."""
        return self._publication is not None

    def fps(self) -> float | None:
        """Frames per second arriving, over the last 64 frames (None before two arrive)."""
        if len(self._arrivals) < 2 or not self.live:
            return None
        span = self._arrivals[-1] - self._arrivals[0]
        return (len(self._arrivals) - 1) / span if span > 0 else None

    def sink_for(self, publication: object) -> Callable[[bytes, int], None]:
        """The tap's sink for one publication (frames of a replaced publication are dropped)."""

        def sink(data: bytes, timestamp: int) -> None:
            if self._publication is not publication:
                return
            if self._offset == -1:
                start = 0 if self._last_out is None else self._last_out + RESTART_GAP
                self._offset = start - timestamp
            out = (timestamp + self._offset) & 0xFFFFFFFF
            self._last_out = out
            self._arrivals.append(time.monotonic())
            frame = EncodedFrame(data, out, is_vp8_keyframe(data))
            for track in list(self.tracks):
                track.offer(frame)
            for listener in list(self.listeners):
                listener(frame)
            VIDEO_FRAMES.inc(len(self.tracks) + len(self.listeners))

        return sink

    def request_keyframe(self) -> None:
        """Ask the publisher for a keyframe, at most every KEYFRAME_REQUEST_INTERVAL_S."""
        now = time.monotonic()
        if (
            self._keyframe_requester is None
            or now - self._last_request < KEYFRAME_REQUEST_INTERVAL_S
        ):
            return
        self._last_request = now
        self._keyframe_requester()
