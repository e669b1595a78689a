"""A bounded expanding-square search for a pad that is not in view (pure).

From the base's surveyed position the vehicle flies legs north, east, south, west, ... of
1, 1, 2, 2, 3, 3, ... times the leg spacing, so each new leg sweeps the strip just beyond the
last one (the IAMSAR expanding square; ArduPilot has no search of its own for PLND, so this is
the pattern a mission planner would fly). The spacing is a fraction of the width in which the
whole pad is in the camera's view at the search height — the narrower image axis, since the
vehicle may face any way: 2 (height · c / f − the pad's half size). The pattern is bounded by
the maximum radius as a square's half side (the leg that would cross it ends on it), and by time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from asset_agent.precland.config import CameraModel, SearchConfig

# north, east, south, west
DIRECTIONS = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))


def leg_spacing(height: float, camera: CameraModel, config: SearchConfig) -> float:
    """The distance between parallel legs (m) at `height` metres above the pad."""
    half_view = height * min(camera.cx / camera.fx, camera.cy / camera.fy)
    width = 2 * max(half_view - config.pad_half_size_m, 0.0)
    return max(config.footprint_fraction * width, config.min_leg_m)


def corners(
    centre: tuple[float, float], spacing: float, max_radius: float
) -> list[tuple[float, float]]:
    """The pattern's corners (north, east), the centre first, none further than `max_radius`
    north or east of it (the leg that would cross that bound ends on it, and the pattern)."""
    cn, ce = centre
    n, e = centre
    out = [(n, e)]
    leg = 0
    while True:
        length = (leg // 2 + 1) * spacing
        dn, de = DIRECTIONS[leg % 4]
        nn = min(max(n + dn * length, cn - max_radius), cn + max_radius)
        ne = min(max(e + de * length, ce - max_radius), ce + max_radius)
        if math.dist((nn, ne), (n, e)) > 1e-6:
            out.append((nn, ne))
        if (nn, ne) != (n + dn * length, e + de * length):
            return out
        n, e = nn, ne
        leg += 1


@dataclass
class ExpandingSquare:
    """The search in progress: which corner is next, and whether it is over."""

    waypoints: list[tuple[float, float]]
    started: float
    config: SearchConfig
    height: float
    index: int = 0

    @classmethod
    def start(
        cls,
        now: float,
        centre: tuple[float, float],
        height: float,
        camera: CameraModel,
        config: SearchConfig,
    ) -> ExpandingSquare:
        """A search around `centre` (local north, east) at `height` above the pad."""
        spacing = leg_spacing(height, camera, config)
        return cls(corners(centre, spacing, config.max_radius_m), now, config, height)

    def target(self, now: float, vehicle_ne: tuple[float, float]) -> tuple[float, float] | None:
        """The corner to fly to now (advancing past a reached one), or None when it is over."""
        if now - self.started > self.config.max_time_s:
            return None
        while self.index < len(self.waypoints):
            wp = self.waypoints[self.index]
            if math.dist(wp, vehicle_ne) > self.config.reached_tolerance_m:
                return wp
            self.index += 1
        return None
