"""`Socket` over an ASGI WebSocket (Starlette's): the sessions' sockets under any ASGI server.

`aerobase server` serves `/ws/asset` and `/ws/operator` natively (native.py); this adapter keeps
the same routes working when the app runs under another ASGI server or uvicorn's own WebSocket
implementation. Sends go through `Sender` (written at once while the socket can take them, else
queued behind a writer task); a delivered handler is fed by a reader task.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable

from fastapi import WebSocket, WebSocketDisconnect

from asynckit.tasks import cancel_and_wait
from server.realtime.frames import (
    BINARY_REFUSED,
    TIMED_OUT,
    UNSUPPORTED_DATA,
    Disconnected,
    Refused,
)
from server.realtime.sender import Sender, SlowReader

log = logging.getLogger(__name__)


class AsgiSocket:
    """An accepted Starlette WebSocket as a `Socket`."""

    def __init__(self, ws: WebSocket, max_queue: int, timeout_s: float) -> None:
        """Wrap `ws` (not yet accepted)."""
        self.ws = ws
        self.sender = Sender(ws, max_queue=max_queue, timeout_s=timeout_s)
        self._done = asyncio.Event()
        self._reader: asyncio.Task[None] | None = None
        self._writer: asyncio.Task[None] | None = None

    async def accept(self) -> None:
        """Accept the socket and start its writer task."""
        await self.ws.accept()
        self._writer = asyncio.create_task(self._write())

    @property
    def written(self) -> int:
        """Frames handed to the ASGI server."""
        return self.sender.written

    @property
    def dropped(self) -> int:
        """Frames refused (queue full, or closing)."""
        return self.sender.dropped

    async def _write(self) -> None:
        try:
            await self.sender.run()
        except (WebSocketDisconnect, SlowReader):
            pass
        except Exception:
            log.exception("WebSocket send failed")
        finally:
            self._done.set()

    async def receive_text(self, timeout_s: float | None = None, waiting: str = "") -> str:
        """The next text message (see `Socket`)."""
        try:
            if timeout_s is None:
                message = await self.ws.receive()
            else:
                message = await asyncio.wait_for(self.ws.receive(), timeout_s)
        except TimeoutError:
            raise Refused(TIMED_OUT, f"no {waiting or 'message'} within {timeout_s:g} s") from None
        except (RuntimeError, WebSocketDisconnect):  # received after the disconnect
            raise Disconnected(1006) from None
        if message["type"] == "websocket.disconnect":
            self._done.set()
            raise Disconnected(int(message.get("code", 1000)))
        text = message.get("text")
        if text is None:
            self.close(UNSUPPORTED_DATA, BINARY_REFUSED)
            raise Disconnected(UNSUPPORTED_DATA)
        return str(text)

    def deliver(self, handler: Callable[[str], None]) -> None:
        """Feed `handler` from a reader task."""
        self._reader = asyncio.create_task(self._read(handler))

    async def _read(self, handler: Callable[[str], None]) -> None:
        try:
            while True:
                text = await self.receive_text()
                try:
                    handler(text)
                except Exception:
                    log.exception("a WebSocket message handler failed")
                    self.close(1011, "internal error")
                    return
        except (Disconnected, Refused):
            self._done.set()

    def pause_reading(self) -> None:
        """Not offered by ASGI: the reader task keeps reading (the ingest's queue absorbs it)."""

    def resume_reading(self) -> None:
        """See `pause_reading`."""

    def send_text(self, text: str | bytes) -> bool:
        """Write now or queue (see `Sender.send_text`)."""
        return self.sender.send_text(text.decode() if isinstance(text, bytes) else text)

    def close(self, code: int, reason: str = "") -> None:
        """Queue a close behind what was sent."""
        self.sender.close(code, reason)

    async def wait_closed(self) -> None:
        """Until the connection is gone; then stop the reader and writer tasks."""
        if self._writer is None:  # never accepted
            return
        await self._done.wait()
        if not self._writer.done() and self.sender.queue:
            # a close queued by the session: let the writer finish it (bounded by its timeout)
            with contextlib.suppress(Exception):
                await asyncio.wait_for(asyncio.shield(self._writer), 2 * self.sender.timeout_s)
        await cancel_and_wait([self._reader, self._writer])
