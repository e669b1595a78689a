"""The sending half of a server WebSocket: frames written at once when the socket can take them,
queued behind a writer task only when it cannot; closable from anywhere.

A frame is handed to the ASGI server straight away (no task switch per frame) as long as nothing
is queued before it and the transport is writable: the ASGI send of a text frame completes
without suspending in that case. When the send has to wait (the peer's TCP window is full), the
half-done send and every later frame go to the writer task, in order. A peer that does not take a
frame within the send timeout (a slow or stalled reader) is closed with 4408 instead of holding
the writer, its queue and its subscriptions forever.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import Coroutine, Generator
from typing import Any

from fastapi import WebSocket

from protocol.codec import encode
from protocol.messages import ErrorPayload, envelope
from server.realtime.frames import TIMED_OUT


class SlowReader(Exception):
    """The peer did not take a frame within the send timeout; its socket was closed."""


class _Resume:
    """Awaitable that finishes a coroutine which suspended on `waiting` outside any task."""

    def __init__(self, coro: Coroutine[Any, Any, Any], waiting: Any) -> None:
        self.coro = coro
        self.waiting = waiting

    def __await__(self) -> Generator[Any, Any, None]:
        waiting = self.waiting
        while True:
            try:
                yield waiting  # the future the send waits on (the transport becoming writable)
            except BaseException as err:  # cancelled or timed out: end the half-done send too
                self.coro.close()
                raise err from None
            try:
                waiting = self.coro.send(None)
            except StopIteration:
                return


class Sender:
    """Serialises sends on one socket and closes it from anywhere (broker callbacks included)."""

    def __init__(self, ws: WebSocket, max_queue: int = 1000, timeout_s: float = 10.0) -> None:
        """Queue at most `max_queue` frames (beyond that `send_text` drops and counts); a frame
        the peer has not taken within `timeout_s` closes the socket."""
        self.ws = ws
        self.max_queue = max_queue
        self.queue: deque[str | tuple[int, str]] = deque()
        self.timeout_s = timeout_s
        self.dropped = 0
        self.written = 0
        self._wake = asyncio.Event()
        self._stuck: _Resume | None = None  # a send that suspended, for the writer to finish
        self._busy = False  # the writer is sending: later frames queue behind it
        self._closing = False
        self._error: BaseException | None = None

    def send_text(self, text: str) -> bool:
        """Write a frame now, or queue it behind earlier ones; False (and counted) when the
        queue is full or the socket is closing."""
        if self._closing or self._error is not None:
            self.dropped += 1
            return False
        if self.queue or self._stuck is not None or self._busy:
            if len(self.queue) >= self.max_queue:
                self.dropped += 1
                return False
            self.queue.append(text)
            self._wake.set()
            return True
        coro = self.ws.send_text(text)
        try:
            waiting = coro.send(None)
        except StopIteration:
            self.written += 1
            return True
        except BaseException as err:  # the peer left, the socket failed: the writer reports it
            self._error = err
            self._wake.set()
            return False
        self._stuck = _Resume(coro, waiting)
        self._wake.set()
        return True

    def send_error(self, code: str, message: str, seq: int | None = None) -> bool:
        """Send an error message (about message `seq` when given)."""
        return self.send_text(
            encode(envelope(ErrorPayload(code=code, message=message[:2000], re_seq=seq)))
        )

    def close(self, code: int, reason: str) -> None:
        """Close the socket once what is queued before has been sent (at once when the queue is
        full: a reader too slow to drain it must not keep its socket open past its session)."""
        if self._closing:
            return
        if len(self.queue) >= self.max_queue:
            self.dropped += len(self.queue)
            self.queue.clear()
        self._closing = True
        self.queue.append((code, reason))
        self._wake.set()

    async def run(self) -> None:
        """Finish sends that had to wait and write what queued behind them, until a close is
        queued (or the socket fails); raises SlowReader after closing a peer that stopped taking
        frames."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            if self._error is not None:
                raise self._error
            self._busy = True
            try:
                if self._stuck is not None:
                    await self._bounded(self._stuck)
                    self._stuck = None
                    self.written += 1
                while self.queue:
                    item = self.queue.popleft()
                    if isinstance(item, tuple):
                        await self._close(item[0], item[1])
                        return
                    await self._bounded(self.ws.send_text(item))
                    self.written += 1
            finally:
                self._busy = False

    async def _bounded(self, send: Any) -> None:
        try:
            await asyncio.wait_for(send, self.timeout_s)
        except TimeoutError:
            self._closing = True
            await self._close(TIMED_OUT, f"a frame not taken within {self.timeout_s:g} s")
            raise SlowReader(f"peer took no frame within {self.timeout_s:g} s") from None

    async def _close(self, code: int, reason: str) -> None:
        # bounded too: the close frame waits behind what the peer has not read
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.ws.close(code, reason[:120]), self.timeout_s)
