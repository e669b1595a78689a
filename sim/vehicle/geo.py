"""Flat-earth conversion between local NED metres and geodetic coordinates around an origin."""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class GeoOrigin:
    """The geodetic point that is local (0, 0, 0): latitude, longitude (degrees), MSL altitude."""

    lat: float
    lon: float
    alt: float

    def to_geodetic(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        """Local NED metres -> (lat deg, lon deg, alt m MSL)."""
        lat = self.lat + math.degrees(n / EARTH_RADIUS_M)
        lon = self.lon + math.degrees(e / (EARTH_RADIUS_M * math.cos(math.radians(self.lat))))
        return lat, lon, self.alt - d

    def to_ned(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m MSL) -> local NED metres."""
        n = math.radians(lat - self.lat) * EARTH_RADIUS_M
        e = math.radians(lon - self.lon) * EARTH_RADIUS_M * math.cos(math.radians(self.lat))
        return n, e, self.alt - alt
