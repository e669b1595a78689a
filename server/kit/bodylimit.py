"""Request bodies over a route's limit are refused with 413 before they are read (ASGI middleware).

A declared `Content-Length` over the limit is answered at once, without reading a byte of the
body; a streamed (chunked) body is counted as it arrives and refused at the first chunk that
crosses the limit. Either way the answer says `Connection: close`, so the server stops reading
the rest of the body instead of draining it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from starlette.exceptions import HTTPException as StarletteHTTPException

from server.kit.errors import ErrorResponse, error_body


class BodyTooLarge(StarletteHTTPException):
    """The request body is over the route's limit (raised from `receive`, rendered as 413)."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, too_large_message(limit), headers={"Connection": "close"})


def too_large_message(limit: int) -> str:
    """The one message of a refused body."""
    return f"the request body is over this route's limit of {limit} bytes"


def _declared_length(scope: Any) -> int | None:
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None  # the HTTP server refuses a malformed Content-Length itself
    return None


class LimitBody:
    """ASGI middleware: at most `default` bytes of body per request, `routes[path]` on those paths."""

    def __init__(self, app: Any, default: int, routes: Mapping[str, int] | None = None) -> None:
        self.app = app
        self.default = default
        self.routes = dict(routes or {})

    def limit_of(self, path: str) -> int:
        """The body limit of a path."""
        return self.routes.get(path, self.default)

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.limit_of(scope["path"])
        declared = _declared_length(scope)
        if declared is not None and declared > limit:
            await _refuse(limit)(scope, receive, send)
            return
        received = 0
        started = False

        async def counted_receive() -> Any:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise BodyTooLarge(limit)
            return message

        async def tracked_send(message: Any) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except BodyTooLarge:
            # normally rendered by the error handlers; this catches a read outside their reach
            if started:
                raise
            await _refuse(limit)(scope, receive, send)


def _refuse(limit: int) -> ErrorResponse:
    return ErrorResponse(
        error_body("too_large", too_large_message(limit)),
        status_code=413,
        headers={"Connection": "close"},
    )
