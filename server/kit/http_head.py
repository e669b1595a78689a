"""uvicorn's HTTP protocol with a limit on how long a request head may take to arrive.

uvicorn (0.55) arms no timer until a first response has been sent: a connection that sends
nothing, or trickles its request line and headers a byte at a time, is held for as long as the
client likes — a WebSocket upgrade request too, since the upgrade is parsed here before the
socket's own limits (`ws_handshake_s`) start. `HeadTimeoutProtocol` arms a timer when the
connection opens and when the first byte of each later request arrives, and disarms it once the
request's headers are complete; when it fires, the client is answered 408 (if it had started a
request) and the connection closed. An idle keep-alive connection between requests is uvicorn's
own `timeout_keep_alive`; a slow body is the application's to bound.
"""

from __future__ import annotations

import asyncio
from typing import Any

from uvicorn.config import Config
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
from uvicorn.server import ServerState

DEFAULT_HEAD_TIMEOUT_S = 10.0
REQUEST_TIMEOUT = (
    b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain; charset=utf-8\r\n"
    b"content-length: 30\r\nconnection: close\r\n\r\nthe request head came too slow"
)


def app_services(config: Config) -> Any:
    """The app's services (`app.state.services`), found through uvicorn's middleware wrappers
    (`.app` chains); None before the app has started."""
    app: Any = config.loaded_app
    for _ in range(16):
        services = getattr(getattr(app, "state", None), "services", None)
        if services is not None:
            return services
        app = getattr(app, "app", None)
        if app is None:
            break
    return None


class HeadTimeoutProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol; a request head must arrive within `http_header_timeout_s`
    (the app's settings) of the connection opening or of the request's first byte."""

    def __init__(
        self,
        config: Config,
        server_state: ServerState,
        app_state: dict[str, Any],
        _loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        super().__init__(config, server_state, app_state, _loop)
        settings = getattr(app_services(config), "settings", None)
        self.head_timeout_s: float = getattr(
            settings, "http_header_timeout_s", DEFAULT_HEAD_TIMEOUT_S
        )
        self.head_timer: asyncio.TimerHandle | None = None
        self.head_started = False

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """The connection opened: its first request head is due within the limit."""
        super().connection_made(transport)
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        """The connection is gone: no timer outlives it."""
        self._disarm()
        super().connection_lost(exc)

    def on_message_begin(self) -> None:
        """A request's first byte: its head is due within the limit (a timer already running,
        from the connection's opening, keeps its deadline)."""
        super().on_message_begin()
        self.head_started = True
        if self.head_timer is None:
            self._arm()

    def on_headers_complete(self) -> None:
        """The head is whole (an upgrade's too, before it is handed on): the limit is met."""
        self._disarm()
        self.head_started = False
        super().on_headers_complete()

    def _arm(self) -> None:
        self.head_timer = self.loop.call_later(self.head_timeout_s, self._head_timed_out)

    def _disarm(self) -> None:
        if self.head_timer is not None:
            self.head_timer.cancel()
            self.head_timer = None

    def _head_timed_out(self) -> None:
        self.head_timer = None
        if self.transport.is_closing():
            return
        if self.head_started:
            self.transport.write(REQUEST_TIMEOUT)
        self.transport.close()
