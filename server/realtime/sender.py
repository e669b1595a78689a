"""The sending half of a server WebSocket: one queue, one writer task, closable from anywhere.

A peer that does not take a frame within the send timeout (a slow or stalled reader) is closed
with 4408 instead of holding the writer, its queue and its subscriptions forever.
"""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import WebSocket

from protocol.codec import encode
from protocol.messages import ErrorPayload, envelope
from server.realtime.frames import TIMED_OUT


class SlowReader(Exception):
    """The peer did not take a frame within the send timeout; its socket was closed."""


class Sender:
    """Serialises sends on one socket and closes it from anywhere (broker callbacks included)."""

    def __init__(self, ws: WebSocket, max_queue: int = 1000, timeout_s: float = 10.0) -> None:
        """Queue at most `max_queue` frames (beyond that `send_text` drops and counts); a frame
        the peer has not taken within `timeout_s` closes the socket."""
        self.ws = ws
        self.queue: asyncio.Queue[str | tuple[int, str]] = asyncio.Queue(max_queue)
        self.timeout_s = timeout_s
        self.dropped = 0

    def send_text(self, text: str) -> bool:
        """Queue a frame; False (and counted) when the queue is full."""
        try:
            self.queue.put_nowait(text)
            return True
        except asyncio.QueueFull:
            self.dropped += 1
            return False

    def send_error(self, code: str, message: str, seq: int | None = None) -> bool:
        """Queue an error message (about message `seq` when given)."""
        return self.send_text(
            encode(envelope(ErrorPayload(code=code, message=message[:2000], re_seq=seq)))
        )

    def close(self, code: int, reason: str) -> None:
        """Close the socket once what is queued before has been sent (at once when the queue is
        full: a reader too slow to drain it must not keep its socket open past its session)."""
        if self.queue.full():
            while not self.queue.empty():
                self.queue.get_nowait()
                self.dropped += 1
        with contextlib.suppress(asyncio.QueueFull):
            self.queue.put_nowait((code, reason))

    async def run(self) -> None:
        """Write queued frames until a close is queued (or the socket fails); raises SlowReader
        after closing a peer that stopped taking frames."""
        while True:
            item = await self.queue.get()
            if isinstance(item, tuple):
                await self._close(item[0], item[1])
                return
            try:
                await asyncio.wait_for(self.ws.send_text(item), self.timeout_s)
            except TimeoutError:
                await self._close(TIMED_OUT, f"a frame not taken within {self.timeout_s:g} s")
                raise SlowReader(f"peer took no frame within {self.timeout_s:g} s") from None

    async def _close(self, code: int, reason: str) -> None:
        # bounded too: the close frame waits behind what the peer has not read
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.ws.close(code, reason[:120]), self.timeout_s)
