"""A jitter buffer that hands a video frame on as soon as its last packet (RTP marker) is in.

aiortc's `JitterBuffer` knows a frame is complete only when a packet of the *next* frame
arrives, so each frame waits one frame interval in it (33 ms at 30 fps) — in the relay that is
added to every viewer's latency. A sender marks the last packet of each frame (RFC 3550 §5.1;
RFC 7741 for VP8; aiortc, libwebrtc and Janus all do), so a frame whose packets are all in, in
order, up to the marked one, is complete. Anything else (a gap, no marker) falls back to aiortc's
own rule. Installed on the relay's receivers only (`forward.tap_receiver`).
"""

from __future__ import annotations

from aiortc.jitterbuffer import JitterBuffer, JitterFrame

JITTER_BUFFER = "_RTCRtpReceiver__jitter_buffer"


class MarkerJitterBuffer(JitterBuffer):
    """aiortc's video jitter buffer, releasing a frame at its marked last packet."""

    def __init__(self) -> None:
        super().__init__(capacity=512, is_video=True)

    def _remove_frame(self, sequence_number: int) -> JitterFrame | None:
        if self._origin is None:
            return None
        packets = []
        timestamp = None
        for count in range(self.capacity):
            packet = self._packets[(self._origin + count) % self._capacity]
            if packet is None:
                break  # a gap: wait (aiortc's rule decides once later packets arrive)
            if timestamp is None:
                timestamp = packet.timestamp
            elif packet.timestamp != timestamp:
                break  # the first frame ended without a marker: aiortc's rule applies
            packets.append(packet)
            if packet.marker:
                self.remove(count + 1)
                data = b"".join(p._data for p in packets)  # type: ignore[attr-defined]
                return JitterFrame(data=data, timestamp=timestamp)
        return super()._remove_frame(sequence_number)
