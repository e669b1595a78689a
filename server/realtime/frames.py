"""What a session needs from its WebSocket (`Socket`), whichever server carries it, and the
errors and close codes of that contract.

Two implementations: `native_socket.NativeSocket` (the hot sockets served straight from the TCP
transport, how `aerobase server` runs) and `asgi_socket.AsgiSocket` (the same sockets through
any ASGI server). Both refuse binary frames with 1003 themselves (the sockets carry JSON text);
a peer silent past a receive's time limit is a `Refused(4408)`, which the session turns into a
close frame with that code (frontend_api.md, "Close codes").
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any, Protocol

from protocol.codec import encode
from protocol.messages import ErrorPayload, envelope

log = logging.getLogger(__name__)

UNSUPPORTED_DATA = 1003  # RFC 6455: a binary frame where only text is accepted
TIMED_OUT = 4408  # our code: too slow to say hello, or to take what is sent
TOO_MANY = 4429  # our code: over a socket's limits (sockets per session, messages per second)
BINARY_REFUSED = "binary frames are not accepted: send JSON text"


def bearer_token(authorization: str, query_token: str | None) -> str | None:
    """A socket's token: `Authorization: Bearer <token>`, else the `token` query parameter
    (browsers cannot set headers on a WebSocket)."""
    scheme, _, value = authorization.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return query_token


class Refused(Exception):
    """The socket must be closed with `code` and `reason`."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"{code} {reason}")
        self.code = code
        self.reason = reason


class Disconnected(Exception):
    """The connection is gone (closed by the peer, by us, or lost) with this close code."""

    def __init__(self, code: int) -> None:
        super().__init__(f"disconnected ({code})")
        self.code = code


class Socket(Protocol):
    """One accepted text WebSocket as the sessions use it: sends never wait (they are written
    at once or queued, in order), a close is queued behind what was sent before it."""

    @property
    def written(self) -> int:
        """Messages handed to the connection."""

    @property
    def dropped(self) -> int:
        """Messages refused: the queue was full or the socket closing."""

    async def accept(self) -> None:
        """Complete the opening handshake."""

    async def receive_text(self, timeout_s: float | None = None, waiting: str = "") -> str:
        """The next text message; `Disconnected` once the connection is gone, `Refused(4408)`
        when nothing came within `timeout_s` (`waiting` names what was expected)."""

    def deliver(self, handler: Callable[[str], None]) -> None:
        """From now on call `handler` (synchronously, in order) with each text message instead
        of queueing it for `receive_text`; messages already queued go to it first."""

    def send_text(self, text: str | bytes) -> bool:
        """Send a text message (`bytes`: already UTF-8); False (and counted) when dropped."""

    def pause_reading(self) -> None:
        """Read nothing more from the peer (TCP pushes back) until `resume_reading`."""

    def resume_reading(self) -> None:
        """Read again."""

    def close(self, code: int, reason: str = "") -> None:
        """Close after what is queued (at once when the queue is full); idempotent."""

    async def wait_closed(self) -> None:
        """Return once the connection is gone (never raises)."""


def error_text(code: str, message: str, seq: int | None = None) -> str:
    """An `error` envelope (about message `seq` when given)."""
    return encode(envelope(ErrorPayload(code=code, message=message[:2000], re_seq=seq)))


def close_on_failure(task: asyncio.Task[Any], sock: Socket, what: str) -> None:
    """When `task` (a session's helper) fails, log it and close `sock` with 1011: the peer
    reconnects to a session whose helpers run."""

    def done(t: asyncio.Task[Any]) -> None:
        if not t.cancelled() and t.exception() is not None:
            log.error("%s failed", what, exc_info=t.exception())
            sock.close(1011, "internal error; reconnect")

    task.add_done_callback(done)
