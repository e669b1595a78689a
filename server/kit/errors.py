"""The typed error tree of the server and the one handler that renders it.

AppError                      {"error": {"code", "message", "details"}}
├── BadRequest        400
├── Unauthorized      401   not logged in, token unknown, expired or ended
├── Forbidden         403   logged in, but the role does not allow it
├── NotFound          404   also for resources of another organisation
├── Conflict          409   name taken, live session, state clash
│   └── EditConflict  409   an edit without If-Match lost a race with another write
├── PreconditionFailed 412  If-Match names none of the resource's current versions
├── TooLarge          413   a request body over the route's limit (server/kit/bodylimit.py)
├── UnsupportedMediaType 415 a body of a content type the route does not read
├── Unprocessable     422   well-formed but invalid
└── RateLimited       429   with Retry-After

Each operation's OpenAPI entry declares the statuses it can answer (server/kit/openapi.py).
"""

from __future__ import annotations

import json
import logging
import math
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.orm.exc import StaleDataError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect

log = logging.getLogger(__name__)


class AppError(Exception):
    """An error with an HTTP status, a stable code and a message meant for people."""

    status = 400
    code = "bad_request"

    def __init__(self, message: str, *, code: str | None = None, details: Any = None) -> None:
        super().__init__(message)
        self.message = message
        if code:
            self.code = code
        self.details = details
        self.headers: dict[str, str] = {}


class BadRequest(AppError):
    """The request cannot be understood."""


class Unauthorized(AppError):
    """Authentication is missing or no longer valid."""

    status, code = 401, "unauthorized"

    def __init__(self, message: str = "authentication required", **kw: Any) -> None:
        super().__init__(message, **kw)
        self.headers = {"WWW-Authenticate": "Bearer"}


class Forbidden(AppError):
    """The caller's role does not allow this."""

    status, code = 403, "forbidden"


class NotFound(AppError):
    """No such resource in the caller's organisation."""

    status, code = 404, "not_found"


class Conflict(AppError):
    """The request clashes with the current state."""

    status, code = 409, "conflict"


class EditConflict(Conflict):
    """Another write of the same resource won the race: read it again and retry."""

    code = "edit_conflict"


class PreconditionFailed(AppError):
    """`If-Match` names none of the resource's current versions: it changed since it was read."""

    status, code = 412, "precondition_failed"


class TooLarge(AppError):
    """The request body is over this route's limit."""

    status, code = 413, "too_large"


class UnsupportedMediaType(AppError):
    """The request body's content type is not one this route reads."""

    status, code = 415, "unsupported_media_type"


class Unprocessable(AppError):
    """Well-formed but semantically invalid."""

    status, code = 422, "validation_error"


class RateLimited(AppError):
    """Too many attempts; retry after the number of seconds in `Retry-After`."""

    status, code = 429, "rate_limited"

    def __init__(self, message: str, retry_after_s: int, **kw: Any) -> None:
        super().__init__(message, **kw)
        self.retry_after_s = max(1, int(retry_after_s))
        self.headers = {"Retry-After": str(self.retry_after_s)}


class Unavailable(AppError):
    """The database cannot be reached now; retry after the seconds in `Retry-After`."""

    status, code = 503, "unavailable"
    RETRY_AFTER_S = 5

    def __init__(
        self,
        message: str = "the server cannot reach its database now; try again shortly",
        **kw: Any,
    ) -> None:
        super().__init__(message, **kw)
        self.headers = {"Retry-After": str(self.RETRY_AFTER_S)}


def unreachable(exc: BaseException) -> bool:
    """Whether `exc` (or what it was raised from) says a connection to the database failed: refused,
    reset or timed out while connecting (asyncpg raises these unwrapped), a connection found dead
    (SQLAlchemy's `connection_invalidated`), or no connection from the pool in time."""
    from sqlalchemy import exc as sa

    seen: BaseException | None = exc
    for _ in range(4):  # the error and what it was raised from, a few links deep
        if seen is None:
            return False
        if isinstance(seen, ConnectionError | TimeoutError | sa.TimeoutError):
            return True
        if isinstance(seen, sa.DBAPIError) and (
            seen.connection_invalidated or isinstance(seen, sa.OperationalError | sa.InterfaceError)
        ):
            return True
        seen = seen.__cause__
    return False


def error_body(code: str, message: str, details: Any = None) -> dict[str, Any]:
    """The one JSON shape of every error response."""
    return {"error": {"code": code, "message": message, "details": details}}


MAX_DETAIL_DEPTH = 32


def non_finite_token(value: float) -> str:
    """How JavaScript and Python spell a non-finite float: "NaN", "Infinity" or "-Infinity"."""
    if math.isnan(value):
        return "NaN"
    return "Infinity" if value > 0 else "-Infinity"


def json_safe(value: Any, depth: int = 0) -> Any:
    """`value` made encodable as strict JSON: a non-finite float becomes its token as a string,
    an unknown object its str(), anything nested deeper than MAX_DETAIL_DEPTH "...".

    Error details echo what the client sent (a bare NaN is valid Python JSON but not JSON), so
    the error encoder must never be the thing that fails.
    """
    if value is None or isinstance(value, str | bool | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else non_finite_token(value)
    if depth >= MAX_DETAIL_DEPTH:
        return "..."
    if isinstance(value, dict):
        return {str(k): json_safe(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [json_safe(v, depth + 1) for v in value]
    return str(value)


class ErrorResponse(JSONResponse):
    """A JSON response that cannot fail to encode (see json_safe)."""

    def render(self, content: Any) -> bytes:
        """Strict JSON (no NaN tokens), UTF-8."""
        return json.dumps(
            json_safe(content), ensure_ascii=False, allow_nan=False, separators=(",", ":")
        ).encode("utf-8")


def answer(exc: AppError) -> JSONResponse:
    """The response an AppError gets. A route returns it itself, instead of raising, when what
    the request wrote must be committed with the refusal (a failed attempt that must count)."""
    return ErrorResponse(
        error_body(exc.code, exc.message, exc.details), status_code=exc.status, headers=exc.headers
    )


CLIENT_CLOSED_REQUEST = 499  # nginx's status for a client that hung up before the answer

_STATUS_CODES = {
    400: "bad_request",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    409: "conflict",
    412: "precondition_failed",
    413: "too_large",
    415: "unsupported_media_type",
    422: "validation_error",
    429: "rate_limited",
}


def _clean_validation(errors: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for e in errors:
        out.append(
            {
                "loc": [str(p) for p in e.get("loc", ())],
                "msg": str(e.get("msg", "")),
                "type": str(e.get("type", "")),
            }
        )
    return out


def install_error_handlers(app: FastAPI) -> None:
    """Render every error, ours or the framework's, in the one shape; never a stack trace."""

    @app.exception_handler(AppError)
    async def _app_error(_: Request, exc: AppError) -> JSONResponse:
        return answer(exc)

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        details = _clean_validation(list(exc.errors()))
        first = details[0] if details else {"loc": [], "msg": "invalid request"}
        where = ".".join(first["loc"])
        return ErrorResponse(
            error_body("validation_error", f"invalid request: {where}: {first['msg']}", details),
            status_code=422,
        )

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = _STATUS_CODES.get(exc.status_code, "error")
        message = str(exc.detail)
        if exc.status_code == 404 and "endpoint" not in request.scope:
            message = _no_route(request.url.path)
        return ErrorResponse(
            error_body(code, message),
            status_code=exc.status_code,
            headers=getattr(exc, "headers", None),
        )

    @app.exception_handler(StaleDataError)
    async def _lost_race(request: Request, _: StaleDataError) -> JSONResponse:
        # the row's version changed between our read and our write (server/kit/etag.py)
        message = "changed by another request at the same time: read it again and reapply the edit"
        lost = PreconditionFailed if "if-match" in request.headers else EditConflict
        return ErrorResponse(error_body(lost.code, message), status_code=lost.status)

    @app.exception_handler(ClientDisconnect)
    async def _hung_up(request: Request, _: ClientDisconnect) -> JSONResponse:
        # the client closed the connection while sending its body (a browser tab closed mid-WHEP
        # offer): no server error, and nobody reads the answer; 499 as nginx logs it
        log.info("the client hung up during %s %s", request.method, request.url.path)
        return ErrorResponse(
            error_body("client_closed_request", "the client closed the connection mid-request"),
            status_code=CLIENT_CLOSED_REQUEST,
        )

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        if unreachable(exc):  # an outage, not a fault of ours: say so, and when to come back
            log.warning("database unreachable on %s %s: %s", request.method, request.url.path, exc)
            away = Unavailable()
            return ErrorResponse(
                error_body(away.code, away.message),
                status_code=away.status,
                headers={**away.headers, "Connection": "close"},
            )
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        # the server drops the connection after an unhandled error (the exception is re-raised to
        # it): say so, or a keep-alive client sends its next request into a closed socket
        return ErrorResponse(
            error_body("internal_error", "internal server error"),
            status_code=500,
            headers={"Connection": "close"},
        )


def _no_route(path: str) -> str:
    """The 404 message of a path no route matches; paths never end with a slash (no redirect)."""
    if path.endswith("/") and path.strip("/"):
        return f"no route {path}: API paths have no trailing slash ({path.rstrip('/')})"
    return f"no route {path}"


class RejectNulBytes:
    """ASGI middleware: a NUL byte in the path or query string is a client error, answered with 422.

    Databases refuse NUL in text (PostgreSQL raises), so it is refused once, here, for every route.
    """

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] in ("http", "websocket"):
            from urllib.parse import unquote_to_bytes

            raw = scope.get("query_string", b"") + scope.get("path", "").encode(
                "utf-8", "surrogateescape"
            )
            if b"\x00" in unquote_to_bytes(raw) or b"\x00" in raw:
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": 1008})
                    return
                response = ErrorResponse(
                    error_body("validation_error", "NUL characters are not allowed in a URL"),
                    status_code=422,
                )
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)
