"""NTRIP streams checked again while they run: a rover's stream ends once its credentials no
longer open its mountpoint (the user disabled or removed from the organisation, the password
changed or reset). Both doors use it: the HTTP port's /ntrip/ routes (ntrip.py) and the caster's
own port (caster.py); what "still allowed" means is the server's (stations/service.py)."""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import AsyncGenerator, AsyncIterator, Awaitable, Callable
from typing import Any

from server.kit.metrics import NTRIP_RECHECKS

log = logging.getLogger(__name__)

# (username, password, organisation id) -> whether those credentials still open that
# organisation's frames
Recheck = Callable[[str, str, Any], Awaitable[bool]]
RECHECK_S = 30.0  # how often a stream's credentials are checked again
Still = Callable[[], Awaitable[bool]]  # a stream's credentials: may they still take its frames?


def still_allowed(
    recheck: Recheck | None, creds: tuple[str, str] | None, organisation_id: Any | None
) -> Still | None:
    """What `rechecked` asks of a stream opened with these (username, password): nothing for an
    anonymous caller (public mountpoints only) or without a `recheck`."""
    if recheck is None or creds is None or organisation_id is None:
        return None
    username, password = creds
    return lambda: recheck(username, password, organisation_id)


async def rechecked(
    frames: AsyncIterator[bytes], still: Still | None, every_s: float
) -> AsyncGenerator[bytes, None]:
    """`frames` until `still()` says no: asked at the first frame after each `every_s` seconds, so
    an account disabled (or removed from the organisation) gets no frame a check later. A check
    that fails (the database away) keeps the stream going: the corrections of a landing UAV do not
    stop for it. Closing this closes `frames`."""
    try:
        next_at = time.monotonic() + every_s
        async for frame in frames:
            if still is not None and time.monotonic() >= next_at:
                try:
                    allowed = await still()
                    outcome = "allowed" if allowed else "ended"
                except Exception:
                    log.warning("ntrip: a stream's credentials could not be checked", exc_info=True)
                    allowed, outcome = True, "failed"
                NTRIP_RECHECKS.labels(outcome).inc()
                if not allowed:
                    log.info("ntrip: a stream's account may no longer take it; ended")
                    return
                next_at = time.monotonic() + every_s
            yield frame
    finally:
        aclose = getattr(frames, "aclose", None)
        if aclose is not None:
            with contextlib.suppress(Exception):
                await aclose()
