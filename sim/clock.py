"""The simulated world's clock: wall time scaled by a speed factor."""

from __future__ import annotations

import asyncio
import time


class SimClock:
    """Simulated seconds since start; `speed` simulated seconds pass per wall second."""

    def __init__(self, speed: float = 1.0) -> None:
        if speed <= 0:
            raise ValueError("speed must be > 0")
        self.speed = speed
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Simulated seconds since the clock started."""
        return (time.monotonic() - self._t0) * self.speed

    async def sleep(self, sim_seconds: float) -> None:
        """Sleep for `sim_seconds` of simulated time."""
        await asyncio.sleep(max(0.0, sim_seconds) / self.speed)
