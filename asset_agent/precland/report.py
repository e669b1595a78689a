"""What a landing did, for the daemon's logs and its `landed` event: the loop's counters, the last
measured fix of the pad (the agent's touchdown offset) and the pad's offset from a GNSS position
(also the landing's prior: `pad_prior`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

EARTH_RADIUS_M = 6_378_137.0


@dataclass
class LandingStats:
    """What precision landing did, for logs and tests."""

    landings: int = 0  # times the loop was started
    frames: int = 0
    ir_readings: int = 0
    targets_sent: int = 0
    measured: int = 0  # control steps with a new (not held) measurement of the pad
    first_sent_t: float | None = None  # sensor clock
    last_sent_t: float | None = None

    @property
    def target_rate_hz(self) -> float | None:
        """LANDING_TARGET messages per sensor-clock second over the span they were sent."""
        if self.first_sent_t is None or self.last_sent_t is None:
            return None
        span = self.last_sent_t - self.first_sent_t
        return (self.targets_sent - 1) / span if span > 0 else None


@dataclass(frozen=True)
class PadFix:
    """The last measured (not held) pad position relative to the vehicle, in sensor seconds."""

    t: float
    rel_ned: tuple[float, float, float]
    sources: tuple[str, ...]

    def touchdown(self, now: float) -> dict[str, Any]:
        """The agent's measured touchdown offset, as scalars for the `landed` event's data."""
        north, east, down = self.rel_ned
        return {
            "offset_m": round(math.hypot(north, east), 3),
            "offset_north_m": round(north, 3),
            "offset_east_m": round(east, 3),
            "fix_height_m": round(down, 2),
            "fix_age_s": round(max(0.0, now - self.t), 2),
            "fix_sources": "+".join(self.sources),
        }


def pad_offset_ned(lat: float, lon: float, pad_lat: float, pad_lon: float) -> tuple[float, float]:
    """(north, east) metres from (lat, lon) to the pad, flat-earth (fine over a landing)."""
    dn = math.radians(pad_lat - lat) * EARTH_RADIUS_M
    de = math.radians(pad_lon - lon) * EARTH_RADIUS_M * math.cos(math.radians(lat))
    return dn, de


def pad_prior(
    section: Any, state: Any, touchdown_height: float
) -> tuple[float, float, float] | None:
    """Pad minus vehicle (NED, camera height as down) from the `[precland]` section's pad (the
    surveyed one, else the autopilot's home) and the GNSS position; None when unknown, or farther
    than `pad_reach_m` (a LAND somewhere else: nothing to look for there)."""
    if (
        section.pad_source == "surveyed"
        and section.pad_lat is not None
        and section.pad_lon is not None
    ):
        pad = (section.pad_lat, section.pad_lon)
    elif state.home_lat is not None and state.home_lon is not None:
        pad = (state.home_lat, state.home_lon)
    else:
        return None
    if state.lat is None or state.lon is None or state.alt_rel is None:
        return None
    dn, de = pad_offset_ned(state.lat, state.lon, *pad)
    if math.hypot(dn, de) > section.pad_reach_m:
        return None
    return dn, de, state.alt_rel + touchdown_height
