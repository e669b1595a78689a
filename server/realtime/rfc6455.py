"""The server side of the WebSocket wire format (RFC 6455), as pure functions and one reader.

No I/O here: `FrameReader.feed` turns received bytes into whole messages and control frames (or
raises `ProtocolError` with the close code RFC 6455 prescribes), `frame` encodes one unmasked
server frame, `accept_key` answers the opening handshake. No extension is negotiated (no
permessage-deflate), so the reserved bits must be 0. A client's frames must be masked (§5.1);
unmasking uses the `websockets` package's C routine when it is importable.
"""

from __future__ import annotations

import base64
import hashlib
import struct
from collections.abc import Callable

_c_mask: Callable[[bytes | bytearray, bytes], bytes] | None
try:  # C speed-up shipped with `websockets` (a dependency); same result either way
    from websockets.speedups import apply_mask as _c_mask
except ImportError:  # pragma: no cover - a platform without the compiled module
    _c_mask = None

CONTINUATION, TEXT, BINARY, CLOSE, PING, PONG = 0x0, 0x1, 0x2, 0x8, 0x9, 0xA
_DATA = (TEXT, BINARY)
_CONTROL = (CLOSE, PING, PONG)
_GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"

# close codes (RFC 6455 §7.4.1)
NORMAL, GOING_AWAY, PROTOCOL_ERROR, UNSUPPORTED = 1000, 1001, 1002, 1003
NO_STATUS, ABNORMAL, INVALID_DATA, POLICY, TOO_BIG = 1005, 1006, 1007, 1008, 1009
INTERNAL_ERROR, SERVICE_RESTART = 1011, 1012
# codes a peer may send in its close frame; 1004-1006 and 1015 are never put on the wire
_SENDABLE = {1000, 1001, 1002, 1003, 1007, 1008, 1009, 1010, 1011, 1012, 1013, 1014}


class ProtocolError(Exception):
    """The peer broke the protocol: close with `code`."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"{code} {reason}")
        self.code = code
        self.reason = reason


def accept_key(key: str) -> str:
    """`Sec-WebSocket-Accept` for a client's `Sec-WebSocket-Key`."""
    return base64.b64encode(hashlib.sha1(key.encode("ascii") + _GUID).digest()).decode("ascii")


def valid_key(key: str) -> bool:
    """A `Sec-WebSocket-Key` is 16 bytes, base64-encoded."""
    try:
        return len(base64.b64decode(key.encode("ascii"), validate=True)) == 16
    except (ValueError, UnicodeEncodeError):
        return False


def frame(opcode: int, payload: bytes) -> bytes:
    """One final, unmasked frame (what a server sends)."""
    n = len(payload)
    if n < 126:
        return bytes((0x80 | opcode, n)) + payload
    if n < 1 << 16:
        return struct.pack("!BBH", 0x80 | opcode, 126, n) + payload
    return struct.pack("!BBQ", 0x80 | opcode, 127, n) + payload


def text_frame(text: str) -> bytes:
    """A text message as one frame."""
    return frame(TEXT, text.encode("utf-8", "surrogatepass"))


def close_frame(code: int, reason: str = "") -> bytes:
    """A close frame with a status code and a reason cut to fit a control frame (123 bytes)."""
    data = reason.encode("utf-8")[:123]
    while data:  # never cut a character in half
        try:
            data.decode("utf-8")
            break
        except UnicodeDecodeError:
            data = data[:-1]
    return frame(CLOSE, struct.pack("!H", code) + data)


def parse_close(payload: bytes) -> tuple[int, str]:
    """The code and reason of a received close frame (1005 when it carries none)."""
    if not payload:
        return NO_STATUS, ""
    if len(payload) == 1:
        raise ProtocolError(PROTOCOL_ERROR, "close frame of one byte")
    (code,) = struct.unpack("!H", payload[:2])
    if code not in _SENDABLE and not 3000 <= code <= 4999:
        raise ProtocolError(PROTOCOL_ERROR, f"invalid close code {code}")
    try:
        reason = payload[2:].decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError(INVALID_DATA, "close reason is not UTF-8") from None
    return code, reason


def _unmask(data: bytes | bytearray, mask: bytes) -> bytes:
    if _c_mask is not None:
        return bytes(_c_mask(data, mask))
    n = len(data)  # pragma: no cover - the pure-Python way, same result
    key = int.from_bytes((mask * (n // 4 + 1))[:n], "little")
    return (int.from_bytes(data, "little") ^ key).to_bytes(n, "little")


class FrameReader:
    """Reassembles a client's frames into messages; holds a partial frame between feeds."""

    def __init__(self, max_size: int) -> None:
        """Messages over `max_size` bytes (whole, after reassembly) are refused with 1009."""
        self.max_size = max_size
        self._buf = bytearray()
        self._frag_opcode: int | None = None  # the data opcode of a fragmented message
        self._frags: list[bytes] = []
        self._frag_size = 0

    def single_text(self, data: bytes) -> bytes | None:
        """The payload when `data` is exactly one whole, final, masked text frame and nothing is
        pending (how a small message usually arrives); None for anything else, which `feed`
        handles (the common case without a list, a loop or a buffer)."""
        if self._buf or self._frag_opcode is not None or len(data) < 6 or data[0] != 0x81:
            return None
        n = data[1] ^ 0x80  # the mask bit set; a length of 126/127 extends it
        if n < 126:
            head = 6
        elif n == 126 and len(data) >= 8:
            n, head = (data[2] << 8) | data[3], 8
        else:
            return None
        if len(data) != head + n or n > self.max_size:
            return None
        return _unmask(data[head:], data[head - 4 : head])

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        """The messages and control frames completed by `data`, in order: (opcode, payload),
        the opcode of a reassembled message being that of its first frame. Raises ProtocolError."""
        buf = self._buf
        if buf:
            buf += data
            view: bytes | bytearray = buf
        else:
            view = data
        out: list[tuple[int, bytes]] = []
        pos, end = 0, len(view)
        while end - pos >= 2:
            b0, b1 = view[pos], view[pos + 1]
            if b0 & 0x70:
                raise ProtocolError(PROTOCOL_ERROR, "reserved bits set (no extension negotiated)")
            if not b1 & 0x80:
                raise ProtocolError(PROTOCOL_ERROR, "client frames must be masked")
            opcode, fin, n = b0 & 0x0F, b0 & 0x80, b1 & 0x7F
            head = 6
            if n == 126:
                if end - pos < 8:
                    break
                (n,) = struct.unpack_from("!H", view, pos + 2)
                head = 8
            elif n == 127:
                if end - pos < 14:
                    break
                (n,) = struct.unpack_from("!Q", view, pos + 2)
                if n >> 63:
                    raise ProtocolError(PROTOCOL_ERROR, "frame length with its top bit set")
                head = 14
            self._check_header(opcode, fin, n)
            if end - pos < head + n:
                break
            mask = bytes(view[pos + head - 4 : pos + head])
            payload = _unmask(view[pos + head : pos + head + n], mask)
            pos += head + n
            message = self._frame(opcode, fin, payload)
            if message is not None:
                out.append(message)
        if buf:
            del buf[:pos]
        elif pos < end:
            self._buf = bytearray(view[pos:])
        return out

    def _check_header(self, opcode: int, fin: int, n: int) -> None:
        if opcode in _CONTROL:
            if not fin:
                raise ProtocolError(PROTOCOL_ERROR, "fragmented control frame")
            if n > 125:
                raise ProtocolError(PROTOCOL_ERROR, "control frame over 125 bytes")
        elif opcode in _DATA:
            if self._frag_opcode is not None:
                raise ProtocolError(PROTOCOL_ERROR, "new message before the last one ended")
            if n > self.max_size:
                raise ProtocolError(TOO_BIG, f"message over {self.max_size} bytes")
        elif opcode == CONTINUATION:
            if self._frag_opcode is None:
                raise ProtocolError(PROTOCOL_ERROR, "continuation frame without a message")
            if self._frag_size + n > self.max_size:
                raise ProtocolError(TOO_BIG, f"message over {self.max_size} bytes")
        else:
            raise ProtocolError(PROTOCOL_ERROR, f"reserved opcode {opcode:#x}")

    def _frame(self, opcode: int, fin: int, payload: bytes) -> tuple[int, bytes] | None:
        if opcode in _CONTROL:
            return opcode, payload
        if opcode != CONTINUATION:
            if fin:
                return opcode, payload
            self._frag_opcode, self._frags, self._frag_size = opcode, [payload], len(payload)
            return None
        self._frags.append(payload)
        self._frag_size += len(payload)
        if not fin:
            return None
        assert self._frag_opcode is not None
        message = (self._frag_opcode, b"".join(self._frags))
        self._frag_opcode, self._frags, self._frag_size = None, [], 0
        return message
