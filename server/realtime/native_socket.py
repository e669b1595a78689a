"""One WebSocket straight on an asyncio transport: the `Socket` (frames.py) that `native.py`
hands the hot sessions.

Frames in (`rfc6455.FrameReader`; one whole text frame per read takes a shortcut) go to the
session's handler inside `data_received`, or to an inbox `receive_text` reads; what is sent is
coalesced into one transport write per `flush_interval_s` (the first frame after a quiet spell at
the end of the loop's current iteration). Control frames are answered here: pong, the closing
handshake (our close frame waits `CLOSE_TIMEOUT_S` for the peer's), keepalive pings (no pong in
`ping_timeout_s`: 1011). A peer that leaves frames untaken for `send_timeout_s` is cut off
(4408); once `max_queue` frames wait for it, later ones are dropped (counted).
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from server.realtime import rfc6455 as ws
from server.realtime.frames import BINARY_REFUSED, TIMED_OUT, Disconnected, Refused

log = logging.getLogger(__name__)
CLOSE_TIMEOUT_S = 5.0  # after our close frame, the peer's answer is awaited this long


@dataclass
class Limits:
    """How a native socket behaves (from Settings and uvicorn's options)."""

    max_size: int = 1 << 20
    max_queue: int = 1000
    send_timeout_s: float = 10.0
    ping_interval_s: float | None = 10.0
    ping_timeout_s: float | None = 10.0
    flush_interval_s: float = 0.01


class NativeSocket:
    """One WebSocket on a transport: the `Socket` the sessions use (see frames.py)."""

    def __init__(
        self,
        transport: asyncio.Transport,
        limits: Limits,
        key: str = "",
        headers: Iterable[tuple[bytes, bytes]] = (),
    ) -> None:
        """A socket whose handshake sent `key`; `headers` go into the 101 answer. Before `accept`
        nothing is written; frames received meanwhile wait."""
        self.transport = transport
        self.limits = limits
        self.key = key
        self.headers = list(headers)
        self.loop = asyncio.get_running_loop()
        self.reader = ws.FrameReader(limits.max_size)
        self.state = "connecting"  # -> open -> closing -> closed
        self.written = 0
        self.dropped = 0
        self.close_code: int | None = None
        self._handler: Callable[[str], None] | None = None
        self._inbox: deque[str] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._out: list[bytes] = []  # frames waiting for the next flush, in order
        self._controls = 0  # of which control frames (not counted as written messages)
        self._flush: asyncio.Handle | None = None
        self._last_flush = 0.0
        self.paused = False  # the transport's buffer is full: frames wait in `_out`
        self._stall: asyncio.TimerHandle | None = None
        self._close_timer: asyncio.TimerHandle | None = None
        self._ping: asyncio.TimerHandle | None = None
        self._pong_due: asyncio.TimerHandle | None = None
        self._closed = self.loop.create_future()

    # --- the handshake ---

    async def accept(self) -> None:
        """Answer 101 (with the server's default headers) and start exchanging frames."""
        if self.state != "connecting":
            return
        head = [
            b"HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n",
            b"Sec-WebSocket-Accept: " + ws.accept_key(self.key).encode("ascii") + b"\r\n",
        ]
        head += [name + b": " + value + b"\r\n" for name, value in self.headers]
        self.transport.write(b"".join(head) + b"\r\n")
        self.state = "open"
        self._schedule_ping()

    def reject(self, status: int, message: str) -> None:
        """Refuse the handshake with an HTTP error (only before `accept`)."""
        if self.state != "connecting":
            return
        body = message.encode("utf-8")
        reason = {400: "Bad Request", 503: "Service Unavailable"}.get(status, "Error")
        self.transport.write(
            f"HTTP/1.1 {status} {reason}\r\ncontent-type: text/plain; charset=utf-8\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n\r\n".encode("latin-1")
            + body
        )
        self.state = "closing"
        self.transport.close()

    # --- receiving ---

    def data_received(self, data: bytes) -> None:
        """Frames in: messages to the handler (or the inbox), control frames answered here."""
        if self.state == "closed":
            return
        single = self.reader.single_text(data)
        if single is not None:
            self._text(single)
            return
        try:
            messages = self.reader.feed(data)
        except ws.ProtocolError as err:
            self._fail(err.code, err.reason)
            return
        for opcode, payload in messages:
            if opcode == ws.TEXT:
                if not self._text(payload):
                    return
            elif opcode == ws.BINARY:
                self._fail(ws.UNSUPPORTED, BINARY_REFUSED)
                return
            elif opcode == ws.PING:
                if self.state == "open":
                    self._write_now(ws.frame(ws.PONG, payload))
            elif opcode == ws.PONG:
                self._pong()
            else:  # CLOSE
                try:
                    code, _reason = ws.parse_close(payload)
                except ws.ProtocolError as err:
                    self._fail(err.code, err.reason)
                    return
                self._peer_closed(code)
                return

    def _text(self, payload: bytes) -> bool:
        """A text message in: to the handler, or the inbox; False once the socket failed."""
        if self.state != "open":
            return True  # after our close frame, data is discarded (RFC 6455 §1.4)
        try:
            text = payload.decode("utf-8")
        except UnicodeDecodeError:
            self._fail(ws.INVALID_DATA, "text message is not valid UTF-8")
            return False
        if self._handler is None:
            self._inbox.append(text)
            self._wake()
            return True
        try:
            self._handler(text)
        except Exception:
            log.exception("a WebSocket message handler failed")
            self._fail(ws.INTERNAL_ERROR, "internal error")
            return False
        return True

    async def receive_text(self, timeout_s: float | None = None, waiting: str = "") -> str:
        """The next text message (see `Socket`)."""
        deadline = None if timeout_s is None else self.loop.time() + timeout_s
        while not self._inbox:
            if self.state in ("closing", "closed"):
                raise Disconnected(self.close_code or ws.ABNORMAL)
            self._waiter = self.loop.create_future()
            try:
                if deadline is None:
                    await self._waiter
                else:
                    await asyncio.wait_for(self._waiter, max(0.0, deadline - self.loop.time()))
            except TimeoutError:
                raise Refused(
                    TIMED_OUT, f"no {waiting or 'message'} within {timeout_s:g} s"
                ) from None
            finally:
                self._waiter = None
        return self._inbox.popleft()

    def pause_reading(self) -> None:
        """Stop reading from the transport (frames already received are still delivered)."""
        if self.state != "closed":
            self.transport.pause_reading()

    def resume_reading(self) -> None:
        """Read from the transport again."""
        if self.state != "closed" and not self.transport.is_closing():
            self.transport.resume_reading()

    def deliver(self, handler: Callable[[str], None]) -> None:
        """Messages go to `handler` from now on (queued ones first)."""
        while self._inbox and self.state == "open":
            handler(self._inbox.popleft())
        self._handler = handler

    def _wake(self) -> None:
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    # --- sending ---

    @property
    def waiting(self) -> int:
        """Frames queued for the next write."""
        return len(self._out)

    def send_text(self, text: str | bytes) -> bool:
        """Queue a text frame (`bytes`: text already encoded as UTF-8) for the next flush;
        False (counted) when closing or too many wait."""
        if self.state != "open" or len(self._out) >= self.limits.max_queue:
            self.dropped += 1
            return False
        self._out.append(
            ws.frame(ws.TEXT, text) if isinstance(text, bytes) else ws.text_frame(text)
        )
        if self._flush is None and not self.paused:
            wait = self._last_flush + self.limits.flush_interval_s - self.loop.time()
            if wait <= 0:
                self._flush = self.loop.call_soon(self._write_out)
            else:
                self._flush = self.loop.call_later(wait, self._write_out)
        return True

    def _write_out(self) -> None:
        self._flush = None
        if self.paused or not self._out or self.state == "closed":
            return
        out, self._out = self._out, []
        self.written += len(out) - self._controls
        self._controls = 0
        self._last_flush = self.loop.time()
        self.transport.write(out[0] if len(out) == 1 else b"".join(out))

    def _write_now(self, data: bytes) -> None:
        """Write a control frame at once, after what is queued (never reordered before it)."""
        self._out.append(data)
        self._controls += 1
        if self._flush is not None:
            self._flush.cancel()
            self._flush = None
        self._write_out()

    def pause_writing(self) -> None:
        """The transport's buffer is full: queue, and give the peer `send_timeout_s`."""
        self.paused = True
        if self._stall is None:
            self._stall = self.loop.call_later(self.limits.send_timeout_s, self._stalled)

    def resume_writing(self) -> None:
        """The peer took its frames: write what queued meanwhile."""
        self.paused = False
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None
        if self._out and self._flush is None:
            self._flush = self.loop.call_soon(self._write_out)

    def _stalled(self) -> None:
        self._stall = None
        reason = f"a frame not taken within {self.limits.send_timeout_s:g} s"
        log.info("closing a WebSocket whose peer stopped reading: %s", reason)
        self.close_code = TIMED_OUT
        self._out.clear()
        self._controls = 0
        self.state = "closing"
        self._wake()
        self.transport.abort()  # its buffer will not drain: a close frame could not get through

    # --- closing ---

    def close(self, code: int, reason: str = "") -> None:
        """Send a close frame after what is queued; the peer's answer (or CLOSE_TIMEOUT_S) ends
        the connection. Before the handshake, a refusal (503)."""
        if self.state == "connecting":
            self.reject(503, reason or "closed before the handshake")
            return
        if self.state != "open":
            return
        if len(self._out) >= self.limits.max_queue:  # a reader that slow does not get the rest
            self.dropped += len(self._out) - self._controls
            self._out.clear()
            self._controls = 0
        self.state, self.close_code = "closing", code
        self._stop_ping()
        self._write_now(ws.close_frame(code, reason))
        self._close_timer = self.loop.call_later(CLOSE_TIMEOUT_S, self.transport.abort)
        self._wake()

    def _fail(self, code: int, reason: str) -> None:
        """RFC 6455 §7.1.7, "Fail the WebSocket Connection": our close frame, then the TCP
        connection closed at once (once the frame is written); nothing more of the peer's is
        read, its answering close frame neither."""
        log.info("closing a WebSocket: %d %s", code, reason)
        self.close(code, reason)
        self.transport.close()

    def _peer_closed(self, code: int) -> None:
        if self.state == "open":  # the peer started the closing handshake: answer it
            self.close_code = code
            self.state = "closing"
            self._stop_ping()
            self._write_now(
                ws.close_frame(code) if code != ws.NO_STATUS else ws.frame(ws.CLOSE, b"")
            )
        self._wake()
        self.transport.close()  # the server closes the TCP connection first (RFC 6455 §7.1.1)

    def shutdown(self) -> None:
        """The server is stopping: 1012 (service restart)."""
        self.close(ws.SERVICE_RESTART, "server restarting")

    def connection_lost(self, exc: BaseException | None) -> None:
        """The TCP connection is gone."""
        self.state = "closed"
        if self.close_code is None:
            self.close_code = ws.ABNORMAL
        for handle in (self._flush, self._stall, self._close_timer):
            if handle is not None:
                handle.cancel()
        self._stop_ping()
        self._out.clear()
        self._controls = 0
        self._wake()
        if not self._closed.done():
            self._closed.set_result(None)

    async def wait_closed(self) -> None:
        """Until the connection is gone."""
        await asyncio.shield(self._closed)

    # --- keepalive ---

    def _schedule_ping(self) -> None:
        if self.limits.ping_interval_s and self.state == "open":
            self._ping = self.loop.call_later(self.limits.ping_interval_s, self._send_ping)

    def _send_ping(self) -> None:
        self._ping = None
        if self.state != "open":
            return
        self._write_now(ws.frame(ws.PING, os.urandom(4)))
        if self.limits.ping_timeout_s:
            self._pong_due = self.loop.call_later(self.limits.ping_timeout_s, self._no_pong)

    def _pong(self) -> None:
        if self._pong_due is not None:
            self._pong_due.cancel()
            self._pong_due = None
            self._schedule_ping()

    def _no_pong(self) -> None:
        self._pong_due = None
        self._fail(ws.INTERNAL_ERROR, "keepalive ping timeout")  # it would not answer a close

    def _stop_ping(self) -> None:
        for handle in (self._ping, self._pong_due):
            if handle is not None:
                handle.cancel()
        self._ping = self._pong_due = None
