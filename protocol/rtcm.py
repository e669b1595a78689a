"""RTCM3 framing shared by every part: CRC-24Q, frame building and a byte-stream reframer.

An RTCM3 frame is: preamble 0xD3, 6 reserved bits + 10-bit payload length, the payload,
and a 24-bit CRC-24Q over everything before it.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

PREAMBLE = 0xD3
MAX_PAYLOAD = 1023
_POLY = 0x1864CFB


def _make_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= _POLY
        table.append(crc & 0xFFFFFF)
    return table


_TABLE = _make_table()


def crc24q(data: bytes, crc: int = 0) -> int:
    """CRC-24Q (Qualcomm) of `data`, as used by RTCM3."""
    for b in data:
        crc = ((crc << 8) & 0xFFFFFF) ^ _TABLE[((crc >> 16) ^ b) & 0xFF]
    return crc


def build_frame(payload: bytes) -> bytes:
    """Wrap a message payload in an RTCM3 frame with its CRC."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"RTCM3 payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    head = bytes([PREAMBLE, (len(payload) >> 8) & 0x03, len(payload) & 0xFF]) + payload
    return head + crc24q(head).to_bytes(3, "big")


def frame_ok(frame: bytes) -> bool:
    """True when `frame` is one complete RTCM3 frame whose CRC matches."""
    if len(frame) < 6 or frame[0] != PREAMBLE:
        return False
    length = ((frame[1] & 0x03) << 8) | frame[2]
    if len(frame) != length + 6:
        return False
    return crc24q(frame[:-3]) == int.from_bytes(frame[-3:], "big")


def message_type(frame: bytes) -> int | None:
    """The 12-bit message number of a frame, or None when it has no payload."""
    if len(frame) < 5:
        return None
    return (frame[3] << 4) | (frame[4] >> 4)


@dataclass
class Reframer:
    """Cuts an arbitrary byte stream into RTCM3 frames, resynchronising after garbage.

    Feed bytes as they arrive; iterate good frames. Bad CRCs and skipped bytes are counted.
    """

    good_frames: int = 0
    bad_frames: int = 0
    skipped_bytes: int = 0
    _buf: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes) -> Iterator[bytes]:
        """Add bytes; yield every complete frame that passes CRC."""
        self._buf.extend(data)
        buf = self._buf
        while True:
            start = buf.find(bytes([PREAMBLE]))
            if start < 0:
                self.skipped_bytes += len(buf)
                buf.clear()
                return
            if start:
                self.skipped_bytes += start
                del buf[:start]
            if len(buf) < 3:
                return
            length = ((buf[1] & 0x03) << 8) | buf[2]
            if buf[1] & 0xFC:
                # reserved bits must be zero: not a frame start
                self.skipped_bytes += 1
                del buf[:1]
                continue
            total = length + 6
            if len(buf) < total:
                return
            frame = bytes(buf[:total])
            if crc24q(frame[:-3]) == int.from_bytes(frame[-3:], "big"):
                self.good_frames += 1
                del buf[:total]
                yield frame
            else:
                self.bad_frames += 1
                self.skipped_bytes += 1
                del buf[:1]
