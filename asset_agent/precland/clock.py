"""The sensors' clock as the agent sees it, followed from the capture timestamps it receives.

Frames and IR readings carry capture timestamps on the sensors' clock (in the simulator, the world
clock). `SensorClock` fits that clock's offset and rate against the agent's monotonic clock, so
fusion, the Kalman filter and the control step all run in sensor-clock seconds.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from collections.abc import Callable


class SensorClock:
    """The sensors' clock as seen from here: rate and offset against `wall` from received stamps.

    now() = rate * wall + offset, with the rate fitted over the last `window_s` wall seconds (or
    fixed) and the offset the largest seen (the least-delayed sample); never goes backwards.
    """

    def __init__(
        self,
        rate: float | None = None,
        window_s: float = 2.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        self.fixed_rate = rate
        self.window_s = window_s
        self.wall = wall
        self._samples: deque[tuple[float, float]] = deque()
        self._last = -math.inf

    @property
    def ready(self) -> bool:
        """True once a timestamp has been seen."""
        return bool(self._samples)

    @property
    def rate(self) -> float:
        """Sensor seconds per wall second."""
        if self.fixed_rate is not None:
            return self.fixed_rate
        s = self._samples
        if len(s) < 3 or s[-1][0] - s[0][0] < 0.3:
            return 1.0 if len(s) < 2 or s[-1][0] == s[0][0] else self._slope()
        return self._slope()

    def _slope(self) -> float:
        n = len(self._samples)
        mw = sum(w for w, _ in self._samples) / n
        mt = sum(t for _, t in self._samples) / n
        var = sum((w - mw) ** 2 for w, _ in self._samples)
        if var <= 0:
            return 1.0
        slope = sum((w - mw) * (t - mt) for w, t in self._samples) / var
        return slope if slope > 0 else 1.0

    def observe(self, ts: float) -> None:
        """A capture timestamp just received."""
        w = self.wall()
        self._samples.append((w, ts))
        while self._samples and w - self._samples[0][0] > self.window_s:
            self._samples.popleft()

    def now(self) -> float:
        """Current sensor-clock time (0.0 before any timestamp)."""
        if not self._samples:
            return 0.0
        r = self.rate
        offset = max(t - r * w for w, t in self._samples)
        self._last = max(self._last, r * self.wall() + offset)
        return self._last

    async def sleep(self, seconds: float) -> None:
        """Sleep this many sensor-clock seconds."""
        await asyncio.sleep(max(0.0, seconds) / self.rate)
