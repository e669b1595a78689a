"""The zones a flight must respect, as the fence and rally points an ArduPilot autopilot takes.

ArduPilot's fence is two-dimensional (AC_PolyFence_loader): polygons (MAV_CMD_NAV_FENCE_POLYGON_
VERTEX_INCLUSION/EXCLUSION, every vertex carrying the polygon's vertex count, at most 255) and
circles (NAV_FENCE_CIRCLE_INCLUSION/EXCLUSION, radius in param1), one return point, and one
altitude ceiling for the whole fence (FENCE_ALT_MAX, metres above home). So:
- every inclusion zone goes up as it is; a polygon with more vertices than `MAX_VERTICES` is
  simplified (Douglas-Peucker in local metres, the tolerance doubled until it fits, at most
  `MAX_SIMPLIFY_M` off the drawn boundary: the server-side path check keeps the exact shape);
- the ceiling is the lowest ceiling of the inclusion zones (a base's operating area: 120 m);
- an exclusion zone goes up only when the path never passes over or under it: a zone with a
  floor or a ceiling that the mission legitimately flies above or below would be breached by a
  fence that has no altitude, so that one is left to the server's check before take-off;
- the return point is the base; the rally points are the plan's (QGroundControl
  `rallyPoints`), altitudes in whole metres as ArduPilot keeps them (int16).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from server.airspace.check import LocalZone, ZoneShape, flight_path, localise
from server.missions.geometry import LocalProjection
from server.missions.items import MissionItem
from server.missions.validate import Home

RETURN_POINT, VERTEX_INCLUSION, VERTEX_EXCLUSION = 5000, 5001, 5002
CIRCLE_INCLUSION, CIRCLE_EXCLUSION, RALLY_POINT = 5003, 5004, 5100
FRAME_GLOBAL, FRAME_GLOBAL_RELATIVE_ALT = 0, 3
MAX_VERTICES = 100
MAX_SIMPLIFY_M = 20.0
MAX_RALLY_POINTS = 10

Vec = tuple[float, float]


@dataclass(frozen=True)
class Fence:
    """What the autopilot is given: fence items, rally items (wire dicts) and the ceiling."""

    items: list[dict[str, Any]]
    rally: list[dict[str, Any]]
    alt_max_m: float | None
    left_to_the_server: list[str]  # exclusion zones not uploaded (the path flies over/under)


def _item(
    command: int, lat: float, lon: float, p1: float = 0.0, alt: float = 0.0
) -> dict[str, Any]:
    frame = FRAME_GLOBAL_RELATIVE_ALT if command == RALLY_POINT else FRAME_GLOBAL
    return {
        "command": command,
        "frame": frame,
        "params": [p1, 0.0, 0.0, 0.0],
        "lat": round(lat, 7),
        "lon": round(lon, 7),
        "alt": alt,
        "autocontinue": True,
    }


def _segment_distance(p: Vec, a: Vec, b: Vec) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    if dx == dy == 0:
        return math.dist(p, a)
    t = max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)))
    return math.dist(p, (a[0] + t * dx, a[1] + t * dy))


def _douglas_peucker(points: Sequence[Vec], tolerance: float) -> list[Vec]:
    if len(points) < 3:
        return list(points)
    keep = [False] * len(points)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        i, j = stack.pop()
        worst, at = 0.0, -1
        for k in range(i + 1, j):
            d = _segment_distance(points[k], points[i], points[j])
            if d > worst:
                worst, at = d, k
        if at >= 0 and worst > tolerance:
            keep[at] = True
            stack += [(i, at), (at, j)]
    return [p for p, kept in zip(points, keep, strict=True) if kept]


def simplify_ring(ring: Sequence[Vec], limit: int = MAX_VERTICES) -> list[Vec]:
    """An open ring with at most `limit` vertices (and at least 3), as close as that allows."""
    pts = list(ring)
    if len(pts) <= limit:
        return pts
    closed = [*pts, pts[0]]
    tolerance = 0.5
    while True:
        out = _douglas_peucker(closed, tolerance)[:-1]
        if len(out) <= limit or tolerance > MAX_SIMPLIFY_M:
            return out if len(out) >= 3 else pts[:: max(1, len(pts) // limit)][:limit]
        tolerance *= 2


def _crosses(local: LocalZone, path: Sequence[Any]) -> bool:
    for seg in path:
        a, b = seg.a[:2], seg.b[:2]
        if math.dist(a, b) == 0:
            if local.inside(a):
                return True
            continue
        if any(inside for _, _, inside in local.pieces(a, b)):
            return True
    return False


def _ceiling_above_home(zone: ZoneShape, home: Home) -> float | None:
    if zone.ceiling_m is None:
        return None
    return zone.ceiling_m - home.alt if zone.amsl else zone.ceiling_m


def build_fence(
    items: Sequence[MissionItem],
    home: Home,
    zones: Sequence[ZoneShape],
    extras: dict[str, Any] | None = None,
) -> Fence:
    """The fence and rally points for flying `items` from `home` within `zones`."""
    proj = LocalProjection(home.lat, home.lon)
    path = flight_path(items, home, proj)
    out: list[dict[str, Any]] = []
    left: list[str] = []
    ceilings: list[float] = []
    for zone in zones:
        local = localise(zone, proj)
        if zone.kind == "exclusion" and _crosses(local, path):
            left.append(zone.name)
            continue
        if zone.kind == "inclusion" and (top := _ceiling_above_home(zone, home)) is not None:
            ceilings.append(top)
        if zone.center is not None:
            command = CIRCLE_INCLUSION if zone.kind == "inclusion" else CIRCLE_EXCLUSION
            out.append(_item(command, zone.center[0], zone.center[1], round(zone.radius_m, 2)))
            continue
        ring = simplify_ring(local.ring)
        command = VERTEX_INCLUSION if zone.kind == "inclusion" else VERTEX_EXCLUSION
        for x, y in ring:
            lat, lon = proj.to_geo(x, y)
            out.append(_item(command, lat, lon, float(len(ring))))
    if out:
        out.append(_item(RETURN_POINT, home.lat, home.lon))
    alt_max = min(ceilings) if ceilings else None
    return Fence(out, rally_items(extras), alt_max if alt_max and alt_max > 0 else None, left)


def rally_items(extras: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The plan's rally points (QGroundControl `rallyPoints.points`: [lat, lon, alt])."""
    rally = (extras or {}).get("rallyPoints")
    points = rally.get("points") if isinstance(rally, dict) else None
    out = []
    for p in points if isinstance(points, list) else []:
        try:
            lat, lon, alt = float(p[0]), float(p[1]), float(p[2])
        except (TypeError, ValueError, IndexError):
            continue
        if -90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt):
            out.append(_item(RALLY_POINT, lat, lon, alt=float(round(alt))))
    return out[:MAX_RALLY_POINTS]
