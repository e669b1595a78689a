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


# --- MAVLink GPS_RTCM_DATA fragmentation --------------------------------------------------
# GPS_RTCM_DATA carries at most 180 bytes. flags: bit 0 = fragmented, bits 1-2 = fragment id
# (0..3), bits 3-7 = sequence id (0..31). A message of up to 180 bytes goes unfragmented; a longer one is
# sent in up to four fragments, and a fragment shorter than 180 bytes ends it, so a message
# that is an exact multiple of 180 bytes is followed by an empty fragment.

MAVLINK_FRAGMENT = 180
MAVLINK_MAX_MESSAGE = 4 * MAVLINK_FRAGMENT


def mavlink_fragments(message: bytes, sequence_id: int) -> list[tuple[int, bytes]]:
    """Split one RTCM message into (flags, data) pairs for GPS_RTCM_DATA."""
    seq = (sequence_id & 0x1F) << 3
    if len(message) <= MAVLINK_FRAGMENT:
        return [(seq, message)]
    if len(message) >= MAVLINK_MAX_MESSAGE:
        # four full fragments leave no room for the terminating empty one
        raise ValueError(f"RTCM message of {len(message)} bytes is too long for GPS_RTCM_DATA")
    chunks = [message[i : i + MAVLINK_FRAGMENT] for i in range(0, len(message), MAVLINK_FRAGMENT)]
    if len(chunks[-1]) == MAVLINK_FRAGMENT:
        chunks.append(b"")
    return [(seq | (fid << 1) | 1, chunk) for fid, chunk in enumerate(chunks)]


@dataclass
class MavlinkReassembler:
    """Rebuilds RTCM messages from GPS_RTCM_DATA fragments (flags, data), as an autopilot does."""

    incomplete: int = 0
    _seq: int | None = None
    _parts: dict[int, bytes] = field(default_factory=dict)

    def push(self, flags: int, data: bytes) -> bytes | None:
        """Add one fragment; return the whole message once it is complete."""
        if not flags & 1:
            self._reset()
            return bytes(data)
        seq, fid = (flags >> 3) & 0x1F, (flags >> 1) & 0x03
        if self._seq is not None and seq != self._seq:
            self._reset()
        self._seq = seq
        self._parts[fid] = bytes(data)
        if len(data) < MAVLINK_FRAGMENT:
            if all(i in self._parts for i in range(fid + 1)):
                message = b"".join(self._parts[i] for i in range(fid + 1))
                self._seq, self._parts = None, {}
                return message
            self._reset()
        return None

    def _reset(self) -> None:
        if self._parts:
            self.incomplete += 1
        self._seq, self._parts = None, {}
