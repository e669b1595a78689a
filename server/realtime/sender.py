"""The sending half of a server WebSocket: one queue, one writer task, closable from anywhere."""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import WebSocket

from protocol.codec import encode
from protocol.messages import ErrorPayload, envelope


class Sender:
    """Serialises sends on one socket and closes it from anywhere (broker callbacks included)."""

    def __init__(self, ws: WebSocket, max_queue: int = 1000) -> None:
        """Queue at most `max_queue` frames; beyond that `send_text` drops and counts."""
        self.ws = ws
        self.queue: asyncio.Queue[str | tuple[int, str]] = asyncio.Queue(max_queue)
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
            encode(envelope(ErrorPayload(code=code, message=message, re_seq=seq)))
        )

    def close(self, code: int, reason: str) -> None:
        """Close the socket once what is queued before has been sent."""
        with contextlib.suppress(asyncio.QueueFull):
            self.queue.put_nowait((code, reason))

    async def run(self) -> None:
        """Write queued frames until a close is queued (or the socket fails)."""
        while True:
            item = await self.queue.get()
            if isinstance(item, tuple):
                with contextlib.suppress(Exception):
                    await self.ws.close(item[0], item[1][:120])
                return
            await self.ws.send_text(item)
