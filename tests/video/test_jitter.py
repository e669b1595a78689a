"""The relay's jitter buffer releases a frame at its marked last packet, not one frame later."""

from __future__ import annotations

from aiortc.jitterbuffer import JitterBuffer
from aiortc.rtp import RtpPacket

from server.video.jitter import MarkerJitterBuffer


def packet(seq: int, ts: int, data: bytes, marker: bool) -> RtpPacket:
    p = RtpPacket(payload_type=96, sequence_number=seq, timestamp=ts, marker=int(marker))
    p._data = data  # type: ignore[attr-defined]  # what the receiver's depayloader sets
    return p


def test_a_frame_leaves_at_its_marker_where_aiortc_waits_for_the_next_frame():
    ours, theirs = MarkerJitterBuffer(), JitterBuffer(capacity=512, is_video=True)
    frame = [packet(10, 3000, b"ab", False), packet(11, 3000, b"cd", True)]
    assert ours.add(frame[0])[1] is None
    out = ours.add(frame[1])[1]
    assert out is not None and (out.data, out.timestamp) == (b"abcd", 3000)
    for p in frame:
        assert theirs.add(p)[1] is None  # aiortc: still waiting
    assert theirs.add(packet(12, 6000, b"ef", False))[1].data == b"abcd"


def test_a_gap_waits_and_a_frame_without_marker_falls_back_to_the_next_timestamp():
    buf = MarkerJitterBuffer()
    assert buf.add(packet(20, 3000, b"a", False))[1] is None
    assert buf.add(packet(22, 3000, b"c", True))[1] is None  # 21 is missing
    out = buf.add(packet(21, 3000, b"b", False))[1]
    assert out is not None and out.data == b"abc"
    assert buf.add(packet(23, 6000, b"x", False))[1] is None  # no marker: wait
    out = buf.add(packet(24, 9000, b"y", True))[1]
    assert out is not None and (out.data, out.timestamp) == (b"x", 6000)
    # one frame leaves per packet: the marked "y" waits in the buffer for the next arrival
    out = buf.add(packet(25, 12000, b"z", True))[1]
    assert out is not None and (out.data, out.timestamp) == (b"y", 9000)
