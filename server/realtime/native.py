"""The hot sockets (`/ws/asset`, `/ws/operator`) served straight from the TCP transport.

uvicorn hands every WebSocket upgrade to the protocol class its `ws` option names; `aerobase
server` names `WebSocketProtocol`. For the two hot paths it answers the handshake itself and
carries frames on a `NativeSocket` (native_socket.py) — no ASGI message per frame, no task switch
per frame: a received text message goes to the session's handler inside `data_received`, and
what is sent to a socket is coalesced into one transport write per `flush_interval_s`. Any other
path is served by uvicorn's own implementation, to which this class hands every callback.

Behaviour kept from the ASGI path: frames over `ws_max_size` close with 1009, a binary frame with
1003, a protocol error with 1002, invalid UTF-8 with 1007; the server pings every
`ws_ping_interval` and drops a peer whose pong is `ws_ping_timeout` late (1011); uvicorn's
shutdown closes every socket with 1012; a peer that leaves frames untaken for `send_timeout_s`
is closed with 4408, and once `max_queue` frames wait for it later ones are dropped (counted).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, cast
from urllib.parse import parse_qsl

from uvicorn.config import WS_PROTOCOLS, Config
from uvicorn.importer import import_from_string
from uvicorn.server import ServerState

from server.kit.http_head import app_services
from server.realtime import rfc6455 as ws
from server.realtime.frames import Disconnected, bearer_token
from server.realtime.native_socket import Limits, NativeSocket

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Handshake:
    """The opening request of a WebSocket, as uvicorn passed it on."""

    path: str
    query: dict[str, str]
    headers: dict[str, str]  # lower-case names

    def token(self) -> str | None:
        """The caller's token (see `frames.bearer_token`)."""
        return bearer_token(self.headers.get("authorization", ""), self.query.get("token"))


def parse_handshake(head: bytes) -> Handshake:
    """The request line and headers uvicorn rebuilt from the upgrade request."""
    lines = head.decode("latin-1").split("\r\n")
    _, target, _ = lines[0].split(" ", 2)
    path, _, query = target.partition("?")
    headers: dict[str, str] = {}
    for line in lines[1:]:
        if not line:
            break
        name, _, value = line.partition(":")
        name = name.strip().lower()
        # repeated headers joined as HTTP says they may be
        headers[name] = f"{headers[name]}, {value.strip()}" if name in headers else value.strip()
    return Handshake(path, dict(parse_qsl(query, keep_blank_values=True)), headers)


@dataclass(frozen=True)
class Route:
    """A path served natively: its coroutine and how many frames may wait for its peer."""

    serve: Callable[[Any, Handshake, Any], Awaitable[None]]  # (socket, handshake, services)
    max_queue: int


ROUTES: dict[str, Route] = {}  # filled by endpoints.py


class WebSocketProtocol(asyncio.Protocol):
    """uvicorn's `ws` protocol class: the hot paths natively, the rest by uvicorn's default."""

    def __init__(
        self, config: Config, server_state: ServerState, app_state: dict[str, Any] | None = None
    ) -> None:
        self.config = config
        self.server_state = server_state
        self.app_state = app_state
        self.transport: asyncio.Transport | None = None
        self.sock: NativeSocket | None = None
        self.other: Any = None  # uvicorn's own protocol, for any other path

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.Transport, transport)  # uvloop's is not a subclass

    def data_received(self, data: bytes) -> None:
        if self.sock is not None:
            self.sock.data_received(data)
        elif self.other is not None:
            self.other.data_received(data)
        else:
            self._upgrade(data)

    def _upgrade(self, head: bytes) -> None:
        """The first call carries the upgrade request: route it."""
        assert self.transport is not None
        handshake = parse_handshake(head)
        route = ROUTES.get(handshake.path)
        if route is None:
            self.other = import_from_string(WS_PROTOCOLS["auto"] or "")(
                config=self.config, server_state=self.server_state, app_state=self.app_state
            )
            self.other.connection_made(self.transport)
            self.other.data_received(head)
            return
        services = app_services(self.config)
        settings = getattr(services, "settings", None)
        limits = Limits(
            max_size=self.config.ws_max_size,
            max_queue=route.max_queue,
            ping_interval_s=self.config.ws_ping_interval,
            ping_timeout_s=self.config.ws_ping_timeout,
        )
        if settings is not None:
            limits.send_timeout_s = settings.ws_send_timeout_s
            limits.flush_interval_s = settings.ws_flush_interval_s
        key = handshake.headers.get("sec-websocket-key", "")
        sock = self.sock = NativeSocket(
            self.transport, limits, key, self.server_state.default_headers
        )
        self.server_state.connections.add(self)  # type: ignore[arg-type]
        if handshake.headers.get("sec-websocket-version") != "13" or not ws.valid_key(key):
            sock.reject(400, "a WebSocket handshake needs version 13 and a valid key")
            return
        if services is None:
            sock.reject(503, "the server is starting")
            return
        task = asyncio.get_running_loop().create_task(self._serve(route, handshake, services))
        self.server_state.tasks.add(task)
        task.add_done_callback(self.server_state.tasks.discard)

    async def _serve(self, route: Route, handshake: Handshake, services: Any) -> None:
        assert self.sock is not None
        start = time.monotonic()
        try:
            await route.serve(self.sock, handshake, services)
        except Disconnected:
            pass
        except Exception:
            log.exception(
                "WebSocket %s failed after %.1f s", handshake.path, time.monotonic() - start
            )
        finally:
            self.sock.close(1000)
            await self.sock.wait_closed()

    def connection_lost(self, exc: Exception | None) -> None:
        if self.sock is not None:
            self.sock.connection_lost(exc)
            self.server_state.connections.discard(self)  # type: ignore[arg-type]
        elif self.other is not None:
            self.other.connection_lost(exc)

    def eof_received(self) -> bool | None:
        if self.other is not None:
            return self.other.eof_received()  # type: ignore[no-any-return]
        return None

    def pause_writing(self) -> None:
        if self.sock is not None:
            self.sock.pause_writing()
        elif self.other is not None:
            self.other.pause_writing()

    def resume_writing(self) -> None:
        if self.sock is not None:
            self.sock.resume_writing()
        elif self.other is not None:
            self.other.resume_writing()

    def shutdown(self) -> None:
        """uvicorn is stopping (only hot sockets are registered here; the other protocol
        registers itself)."""
        if self.sock is not None:
            self.sock.shutdown()
