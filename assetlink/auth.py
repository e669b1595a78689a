"""HTTP calls of an asset's session: log in with name and secret, renew, log out.

Failures raise the typed errors below, translated from httpx at this edge:

    AuthError
    ├── BadCredentials      401 on login: wrong name or secret (or the asset was deleted)
    ├── SessionGone         401 on renew: the session ended; log in again
    ├── SessionActive       409: another live session of this asset exists
    ├── RateLimited         429: wait `retry_after` seconds
    └── ServerUnavailable   network error, timeout, 5xx or an unreadable answer (a 503's
                            `Retry-After`, the server's database away, in `retry_after`)
"""

from __future__ import annotations

import logging
import time
from datetime import UTC, datetime

import httpx

from assetlink.outbox import Token

log = logging.getLogger(__name__)


class AuthError(Exception):
    """A session call failed; `retry_after`: seconds the server asked to wait (0: none)."""

    retry_after: float = 0.0


class BadCredentials(AuthError):
    """The server refused the asset's name and secret."""


class SessionGone(AuthError):
    """The token's session no longer exists."""


class SessionActive(AuthError):
    """Another live session of this asset exists."""


class RateLimited(AuthError):
    """The server asks to wait before trying again."""

    def __init__(self, message: str, retry_after: float):
        """Keep the server's Retry-After, in seconds."""
        super().__init__(message)
        self.retry_after = retry_after


class ServerUnavailable(AuthError):
    """The server could not be reached or answered with an error of its own; `retry_after`:
    the seconds a 503 asked to wait (0 when it named none)."""

    def __init__(self, message: str, retry_after: float = 0.0):
        """Keep the server's Retry-After, if it sent one."""
        super().__init__(message)
        self.retry_after = retry_after


def parse_expiry(value: str) -> float:
    """An ISO 8601 timestamp (naive means UTC) as unix seconds."""
    moment = datetime.fromisoformat(value)
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    return moment.timestamp()


def _retry_after(response: httpx.Response) -> float:
    raw = response.headers.get("retry-after", "")
    try:
        return max(0.0, float(raw))
    except ValueError:
        try:
            when = datetime.strptime(raw, "%a, %d %b %Y %H:%M:%S GMT").replace(tzinfo=UTC)
        except ValueError:
            return 1.0
        return max(0.0, when.timestamp() - time.time())


class SessionClient:
    """Login, renew and logout against `{server_url}/api/v1/...`."""

    def __init__(self, server_url: str, name: str, secret: str, http: httpx.AsyncClient):
        """Use `http` (owned by the caller) to reach `server_url`."""
        self._base = server_url.rstrip("/")
        self._name = name
        self._secret = secret
        self._http = http

    async def login(self, force: bool = False) -> Token:
        """Open a session for the asset; `force` takes over a live one."""
        body = {"name": self._name, "secret": self._secret, "force": force}
        response = await self._post("/api/v1/assets/login", json=body)
        if response.status_code == 401:
            raise BadCredentials(f"login of asset {self._name!r} refused: bad credentials")
        if response.status_code == 409:
            raise SessionActive(f"asset {self._name!r} already has a live session")
        token = self._token(response)
        log.info("logged in to %s as asset %r", self._base, self._name)
        return token

    async def renew(self, token: str) -> Token:
        """Exchange the session's token for a new one (the old one stops working)."""
        response = await self._post("/api/v1/auth/renew", token=token)
        if response.status_code in (401, 403):
            raise SessionGone("the session ended; log in again")
        return self._token(response)

    async def logout(self, token: str) -> None:
        """End the session; a session already gone is not an error."""
        response = await self._post("/api/v1/auth/logout", token=token)
        if response.status_code not in (200, 204, 401, 403):
            self._check(response)

    async def _post(
        self, path: str, *, json: object = None, token: str | None = None
    ) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        try:
            return await self._http.post(self._base + path, json=json, headers=headers)
        except httpx.HTTPError as err:
            raise ServerUnavailable(f"POST {path}: {type(err).__name__}: {err}") from err

    def _check(self, response: httpx.Response) -> None:
        if response.status_code == 429:
            raise RateLimited("rate limited by the server", _retry_after(response))
        if response.status_code >= 300:
            wait = _retry_after(response) if response.status_code == 503 else 0.0
            raise ServerUnavailable(
                f"POST {response.request.url.path} answered {response.status_code}", wait
            )

    def _token(self, response: httpx.Response) -> Token:
        self._check(response)
        try:
            body = response.json()
            return Token(str(body["access_token"]), parse_expiry(str(body["expires_at"])))
        except (ValueError, KeyError, TypeError) as err:
            raise ServerUnavailable(f"unreadable token answer: {err}") from err
