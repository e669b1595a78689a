"""Wind the simulated vehicle flies in: the weather's steady wind plus discrete gusts, and what
a multirotor cannot lean into.

The steady part is the weather's (`sim/weather.py`: a mean wind wandering slowly, turbulence
and random gust events, settable with `Weather.force(wind_mps=, direction_deg=)`). On top of it
`Weather.gust(...)` schedules a **discrete gust** with the "1 - cosine" shape of the classic
gust models (MIL-F-8785C and CS-25's discrete gust): over `duration_s` the gust's speed rises
from 0 to `peak_mps` and back, `peak/2 * (1 - cos(2 pi t / duration))`, blowing FROM
`direction_deg` (meteorological convention, as the weather's direction).

The vehicle's position controller learns a steady wind and rejects it (`Dynamics`,
`wind_adapt_s`); a change it has not learnt leaks into its ground speed (`wind_leak`). What no
controller rejects is wind beyond what the airframe can lean into: past `authority_mps` (the
wind a multirotor holds station in at its tilt limit, about its top speed) the excess carries
the vehicle downwind at that speed (`overpowering`). That is what pushes a small copter across
a fence in a strong gust.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Gust:
    """A discrete 1 - cosine gust: `peak_mps` from `direction_deg`, starting at `start_s`."""

    start_s: float
    peak_mps: float
    direction_deg: float
    duration_s: float

    def speed(self, t: float) -> float:
        """The gust's speed at simulated time `t` (0 outside it)."""
        x = (t - self.start_s) / self.duration_s
        if not 0.0 <= x <= 1.0:
            return 0.0
        return self.peak_mps / 2.0 * (1.0 - math.cos(2.0 * math.pi * x))

    def over(self, t: float) -> bool:
        """True once the gust has passed."""
        return t > self.start_s + self.duration_s


def from_direction(speed_mps: float, direction_deg: float) -> tuple[float, float]:
    """Air velocity (north, east) of wind of `speed_mps` blowing FROM `direction_deg`."""
    rad = math.radians(direction_deg)
    return -speed_mps * math.cos(rad), -speed_mps * math.sin(rad)


def overpowering(wind_ne: tuple[float, float], authority_mps: float) -> tuple[float, float]:
    """The part of the wind beyond what the vehicle can lean into: it drifts with it."""
    speed = math.hypot(*wind_ne)
    if speed <= authority_mps or speed == 0.0:
        return 0.0, 0.0
    k = (speed - authority_mps) / speed
    return wind_ne[0] * k, wind_ne[1] * k
