"""What a daemon's link is configured with, and the reconnect delay those settings bound.

`LinkSettings` covers the state file, the login and reconnecting; its `Traffic` how each
connection paces its messages. The defaults suit a daemon; tests shorten the backoff.
"""

from __future__ import annotations

import random
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Traffic:
    """How each connection paces its messages and checks the server is there.

    `heartbeat_s` overrides the server's ping interval (a pong missing for that long closes the
    connection); `batch` is how many outbox entries are taken per send; `window` bounds messages
    sent and not yet acked; `max_rate`/`burst` pace every send and must stay under the server's
    per-socket limit (ws_rate_per_s 200 / ws_burst 400 by default), since it drops the excess.
    """

    heartbeat_s: float | None = None
    batch: int = 256
    window: int = 4096
    max_rate: float = 150.0
    burst: float = 300.0


@dataclass(frozen=True, slots=True)
class LinkSettings:
    """How a link keeps its state, logs in and reconnects; `traffic` is per connection.

    `max_outbox` bounds the on-disk queue (the oldest are dropped past it); `backoff_min`/
    `backoff_max` bound the reconnect delay (exponential, full jitter); `force_login` ends
    another live session of the asset; `command_memory_s` is how long finished command ids are
    remembered (a redelivered one gets its first result back, not a second run).
    """

    version: str = "0.1.0"
    max_outbox: int = 100_000
    backoff_min: float = 0.5
    backoff_max: float = 30.0
    connect_timeout: float = 10.0
    force_login: bool = False
    command_memory_s: float = 7 * 86400
    traffic: Traffic = Traffic()


def backoff_delay(attempt: int, low: float, high: float, rng: random.Random) -> float:
    """Exponential backoff with full jitter: uniform in [0, min(high, low * 2**attempt)]."""
    cap = min(high, low * (2 ** min(attempt, 62)))
    return rng.uniform(0, cap)
