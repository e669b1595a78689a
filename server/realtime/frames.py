"""Reading one frame from a server WebSocket: text only, within a time limit, as values or typed errors.

Starlette's `receive_text` fails with a bare KeyError on a binary frame; here a binary frame is a
`Refused(1003)` and a peer silent past the limit a `Refused(4408)`, which the sessions turn into a
close frame with that code (frontend_api.md, "Close codes").
"""

from __future__ import annotations

import asyncio

from fastapi import WebSocket, WebSocketDisconnect

UNSUPPORTED_DATA = 1003  # RFC 6455: a binary frame where only text is accepted
TIMED_OUT = 4408  # our code: too slow to say hello, or to take what is sent
TOO_MANY = 4429  # our code: over a socket's limits (sockets per session, messages per second)


class Refused(Exception):
    """The socket must be closed with `code` and `reason`."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(f"{code} {reason}")
        self.code = code
        self.reason = reason


async def receive_text(ws: WebSocket, timeout_s: float | None = None, waiting: str = "") -> str:
    """The next text frame; WebSocketDisconnect once the peer left, Refused for a binary frame or
    for nothing within `timeout_s` (`waiting` says what was expected, for the close reason)."""
    try:
        if timeout_s is None:
            message = await ws.receive()  # the hot path: no wait_for wrapper per frame
        else:
            message = await asyncio.wait_for(ws.receive(), timeout_s)
    except TimeoutError:
        raise Refused(TIMED_OUT, f"no {waiting or 'message'} within {timeout_s:g} s") from None
    if message["type"] == "websocket.disconnect":
        raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
    text = message.get("text")
    if text is None:
        raise Refused(UNSUPPORTED_DATA, "binary frames are not accepted: send JSON text")
    return str(text)
