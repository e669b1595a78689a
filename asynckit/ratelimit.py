"""A token bucket: the one rate limiter of the server (refuses) and the daemons' link (paces)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable


class TokenBucket:
    """`rate` tokens a second on average, at most `burst` at once; starts full."""

    def __init__(
        self, rate: float, burst: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        """Start full."""
        if rate <= 0 or burst < 1:
            raise ValueError("rate must be positive and burst at least 1")
        self.rate = rate
        self.burst = burst
        self._clock = clock
        self._tokens = burst
        self._at = clock()

    def delay(self) -> float:
        """Take a token and return 0, or return how long to wait before one is available."""
        now = self._clock()
        self._tokens = min(self.burst, self._tokens + (now - self._at) * self.rate)
        self._at = now
        if self._tokens >= 1:
            self._tokens -= 1
            return 0.0
        return (1 - self._tokens) / self.rate

    def take(self) -> bool:
        """Take a token if one is available; False means refuse (nothing is taken). (`delay`
        inlined: the server asks once per message received.)"""
        now = self._clock()
        tokens = self._tokens + (now - self._at) * self.rate
        if tokens > self.burst:
            tokens = self.burst
        self._at = now
        if tokens >= 1:
            self._tokens = tokens - 1
            return True
        self._tokens = tokens
        return False

    def slow_down(self, factor: float = 0.5, min_rate: float = 1.0) -> None:
        """Cut the rate and the burst by `factor` (the other side said we were too fast)."""
        self.rate = max(min_rate, self.rate * factor)
        self.burst = max(1.0, self.burst * factor)
        self._tokens = min(self._tokens, self.burst)

    async def acquire(self) -> None:
        """Wait until a token is available and take it."""
        # Pacing by the clock, not waiting for another task: nothing to signal an Event.
        while (wait := self.delay()) > 0:  # noqa: ASYNC110
            await asyncio.sleep(wait)
