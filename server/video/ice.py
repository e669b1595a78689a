"""ICE servers for viewers and the relay: STUN as configured, TURN with coturn REST credentials.

coturn's `use-auth-secret` scheme (the "TURN REST API" draft): the username is
`<expiry unix time>:<user id>` and the password `base64(HMAC-SHA1(secret, username))`; coturn
recomputes the password from its `static-auth-secret` and refuses the pair once the expiry passes.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import time
from dataclasses import dataclass

from server.config import Settings


@dataclass(frozen=True)
class IceServer:
    """One entry of RTCConfiguration.iceServers."""

    urls: list[str]
    username: str | None = None
    credential: str | None = None


def turn_credentials(secret: str, user: str, ttl_s: int, now: float | None = None) -> IceServer:
    """A username and password coturn accepts until now + ttl_s (no URLs yet)."""
    expiry = int(now if now is not None else time.time()) + ttl_s
    username = f"{expiry}:{user}"
    digest = hmac.new(secret.encode(), username.encode(), hashlib.sha1).digest()
    return IceServer(urls=[], username=username, credential=base64.b64encode(digest).decode())


def ice_servers(settings: Settings, user: str, now: float | None = None) -> list[IceServer]:
    """The ICE servers a peer identified as `user` should use (empty: host candidates only)."""
    out: list[IceServer] = []
    if settings.video_stun_urls:
        out.append(IceServer(urls=list(settings.video_stun_urls)))
    if settings.video_turn_urls and settings.video_turn_secret:
        cred = turn_credentials(settings.video_turn_secret, user, settings.video_turn_ttl_s, now)
        out.append(IceServer(list(settings.video_turn_urls), cred.username, cred.credential))
    return out
