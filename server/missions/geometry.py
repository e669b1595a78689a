"""Pure geometry on small areas: great-circle distance, a local east/north projection, polygons."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

EARTH_RADIUS_M = 6_371_008.8  # mean radius (IUGG)
Point = tuple[float, float]  # (x east, y north) in metres, or (lon, lat) in degrees


def haversine_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance in metres between two WGS84 points (degrees)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp, dl = p2 - p1, math.radians(lon2 - lon1)
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(a)))


@dataclass(frozen=True)
class LocalProjection:
    """Equirectangular east/north metres around an origin: exact enough over a few kilometres."""

    lat0: float
    lon0: float

    @property
    def _kx(self) -> float:
        return math.radians(1.0) * EARTH_RADIUS_M * math.cos(math.radians(self.lat0))

    @property
    def _ky(self) -> float:
        return math.radians(1.0) * EARTH_RADIUS_M

    def to_local(self, lat: float, lon: float) -> Point:
        """(lat, lon) degrees -> (east, north) metres from the origin."""
        dlon = (lon - self.lon0 + 180.0) % 360.0 - 180.0
        return dlon * self._kx, (lat - self.lat0) * self._ky

    def to_geo(self, x: float, y: float) -> tuple[float, float]:
        """(east, north) metres -> (lat, lon) degrees."""
        lon = self.lon0 + x / self._kx
        lon = (lon + 180.0) % 360.0 - 180.0
        return self.lat0 + y / self._ky, lon


def open_ring(ring: Sequence[Point]) -> list[Point]:
    """The ring without its closing point (GeoJSON repeats the first point at the end)."""
    pts = [(float(a), float(b)) for a, b in ring]
    if len(pts) > 1 and pts[0] == pts[-1]:
        pts.pop()
    return pts


def distinct_points(ring: Sequence[Point]) -> int:
    """How many different points a ring has."""
    return len(set(open_ring(ring)))


def ring_area(ring: Sequence[Point]) -> float:
    """Signed area (shoelace) of a planar ring: positive when counter-clockwise."""
    pts = open_ring(ring)
    s = 0.0
    for i, (x1, y1) in enumerate(pts):
        x2, y2 = pts[(i + 1) % len(pts)]
        s += x1 * y2 - x2 * y1
    return s / 2.0


def _orient(a: Point, b: Point, c: Point) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a: Point, b: Point, p: Point) -> bool:
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def segments_intersect(a: Point, b: Point, c: Point, d: Point, eps: float = 1e-9) -> bool:
    """True when segment ab touches or crosses segment cd (collinear overlaps included)."""
    d1, d2 = _orient(c, d, a), _orient(c, d, b)
    d3, d4 = _orient(a, b, c), _orient(a, b, d)
    if ((d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)) and (
        (d3 > eps and d4 < -eps) or (d3 < -eps and d4 > eps)
    ):
        return True
    return (
        (abs(d1) <= eps and _on_segment(c, d, a))
        or (abs(d2) <= eps and _on_segment(c, d, b))
        or (abs(d3) <= eps and _on_segment(a, b, c))
        or (abs(d4) <= eps and _on_segment(a, b, d))
    )


def _folds_back(a: Point, b: Point, c: Point) -> bool:
    """True when the path a -> b -> c turns back on itself along one line."""
    ux, uy, vx, vy = b[0] - a[0], b[1] - a[1], c[0] - b[0], c[1] - b[1]
    cross, dot = ux * vy - uy * vx, ux * vx + uy * vy
    scale = math.hypot(ux, uy) * math.hypot(vx, vy)
    return abs(cross) <= 1e-12 * max(scale, 1e-30) and dot < 0


def self_intersections(ring: Sequence[Point]) -> list[tuple[int, int]]:
    """Pairs of edges (i, j) of a ring that touch or cross, other than neighbours sharing a vertex.

    Edge i runs from point i to point i+1 of the open ring. Repeated consecutive points are
    dropped first. O(n²), fine for the few hundred vertices a survey area has.
    """
    pts: list[Point] = []
    for p in open_ring(ring):
        if not pts or p != pts[-1]:
            pts.append(p)
    if len(pts) > 1 and pts[0] == pts[-1]:
        pts.pop()
    n = len(pts)
    found = []
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                # neighbours share one vertex; they clash only when one folds back onto the other
                first, second = (
                    ((a, b), (pts[j], pts[(j + 1) % n]))
                    if j == i + 1
                    else ((pts[j], pts[(j + 1) % n]), (a, b))
                )
                if _folds_back(first[0], first[1], second[1]):
                    found.append((i, j))
                continue
            if segments_intersect(a, b, pts[j], pts[(j + 1) % n]):
                found.append((i, j))
    return found


def polyline_length_m(points: Sequence[tuple[float, float]]) -> float:
    """Length in metres of a path of (lat, lon) points."""
    return sum(haversine_m(a[0], a[1], b[0], b[1]) for a, b in itertools.pairwise(points))


def rotate(p: Point, angle_rad: float) -> Point:
    """Rotate a planar point counter-clockwise about the origin."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return p[0] * c - p[1] * s, p[0] * s + p[1] * c


def scanline(ring: Sequence[Point], y: float) -> list[tuple[float, float]]:
    """The (x_from, x_to) spans where the horizontal line at `y` lies inside a planar ring."""
    pts = open_ring(ring)
    xs: list[float] = []
    n = len(pts)
    for i in range(n):
        (x1, y1), (x2, y2) = pts[i], pts[(i + 1) % n]
        if y1 == y2:
            continue
        # half-open rule: a vertex exactly on the line counts once
        if (y1 <= y < y2) or (y2 <= y < y1):
            xs.append(x1 + (y - y1) * (x2 - x1) / (y2 - y1))
    xs.sort()
    return [(xs[k], xs[k + 1]) for k in range(0, len(xs) - 1, 2)]
