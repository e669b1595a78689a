"""The video domain's errors, in the server's one error tree (server/kit/errors.py)."""

from __future__ import annotations

from typing import Any

from server.kit.errors import AppError


class ViewerLimit(AppError):
    """The asset already has as many viewers as allowed; retry later (503 with Retry-After)."""

    status, code = 503, "viewer_limit"

    def __init__(self, message: str, retry_after_s: int, **kw: Any) -> None:
        super().__init__(message, **kw)
        self.headers = {"Retry-After": str(max(1, int(retry_after_s)))}


class GatewayUnavailable(AppError):
    """The media gateway cannot be reached or refused the request (503 with Retry-After)."""

    status, code = 503, "gateway_unavailable"

    def __init__(self, message: str, retry_after_s: int = 5, **kw: Any) -> None:
        super().__init__(message, **kw)
        self.headers = {"Retry-After": str(max(1, int(retry_after_s)))}


class UnsupportedMediaType(AppError):
    """The body is not of the content type the endpoint takes."""

    status, code = 415, "unsupported_media_type"
