"""Zones as values: their validation, whether they are active, their shape for the check."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import ValidationError

from server.airspace.check import ZoneShape
from server.airspace.models import AirspaceZone, AltitudeRef, ZoneKind
from server.airspace.schemas import ZoneIn
from server.missions.geometry import LocalProjection, distinct_points, open_ring, self_intersections
from server.missions.validate import Problem, check_latlon

DEFAULT_BASE_CEILING_M = 120.0  # EU open category: 120 m above the take-off point


def zone_problems(zone: ZoneIn, where: str = "") -> list[Problem]:
    """What pydantic cannot say about a zone: a simple ring, a circle's radius, its band."""
    at = f"{where}." if where else ""
    problems: list[Problem] = []
    geometry = zone.geometry
    if geometry.type == "Point":
        lon, lat = geometry.coordinates[0], geometry.coordinates[1]
        problems += check_latlon(f"{at}geometry.coordinates", lat, lon)
        if zone.radius_m is None:
            problems.append(
                Problem(f"{at}radius_m", "a Point zone is a circle: give its radius_m", None)
            )
    else:
        ring = geometry.coordinates[0]
        bad = [k for k, pos in enumerate(ring) if len(pos) not in (2, 3)]
        if bad:
            return [
                Problem(
                    f"{at}geometry.coordinates[0][{bad[0]}]",
                    "a position is [lon, lat] or [lon, lat, alt]",
                    len(ring[bad[0]]),
                    2,
                )
            ]
        points = [(p[0], p[1]) for p in ring]
        for k, (lon, lat) in enumerate(points):
            problems += check_latlon(f"{at}geometry.coordinates[0][{k}]", lat, lon)
        if problems:
            return problems
        n = distinct_points(points)
        if n < 3:
            problems.append(
                Problem(f"{at}geometry", "a polygon needs at least 3 distinct points", n, 3)
            )
        else:
            pts = open_ring(points)
            proj = LocalProjection(
                sum(p[1] for p in pts) / len(pts), sum(p[0] for p in pts) / len(pts)
            )
            local = [proj.to_local(lat, lon) for lon, lat in pts]
            for i, j in self_intersections(local):
                problems.append(
                    Problem(
                        f"{at}geometry",
                        f"the polygon intersects itself: edge {i} meets edge {j}",
                        [i, j],
                    )
                )
        if zone.radius_m is not None:
            problems.append(
                Problem(f"{at}radius_m", "only a Point zone (a circle) has a radius", zone.radius_m)
            )
    if zone.floor_m is not None and zone.ceiling_m is not None and zone.floor_m >= zone.ceiling_m:
        problems.append(
            Problem(f"{at}ceiling_m", "the ceiling must be above the floor", zone.ceiling_m)
        )
    for k, window in enumerate(zone.windows or []):
        if window.end <= window.start:
            problems.append(
                Problem(f"{at}windows[{k}]", "a window must end after it starts", str(window.end))
            )
    return problems


def with_defaults(zone: ZoneIn) -> ZoneIn:
    """A base's inclusion zone (its operating area) without a ceiling gets 120 m above it."""
    if (
        zone.base_id is not None
        and zone.kind == ZoneKind.inclusion
        and zone.ceiling_m is None
        and zone.altitude_ref == AltitudeRef.base
    ):
        return zone.model_copy(update={"ceiling_m": DEFAULT_BASE_CEILING_M})
    return zone


def pydantic_problems(err: ValidationError, where: str) -> list[Problem]:
    """A pydantic error as problems named like ours (`features[3].properties.kind`)."""
    out = []
    for e in err.errors():
        loc = [str(x) for x in e["loc"]]
        path = ".".join(loc) if loc else ""
        if loc and loc[0] != "geometry":
            path = f"properties.{path}"
        value = e.get("input")
        if not isinstance(value, str | int | float | bool | type(None)):
            value = None
        out.append(Problem(f"{where}.{path}" if path else where, e["msg"], value))
    return out


def is_active(zone: AirspaceZone, at: datetime) -> bool:
    """Always-active, or `at` falls in one of its windows."""
    if zone.windows is None:
        return True
    for w in zone.windows:
        start, end = datetime.fromisoformat(w["start"]), datetime.fromisoformat(w["end"])
        if start <= at < end:
            return True
    return False


def shape_of(zone: AirspaceZone) -> ZoneShape:
    """The zone as the path check sees it."""
    g: dict[str, Any] = zone.geometry
    common: dict[str, Any] = {
        "id": str(zone.id),
        "name": zone.name,
        "kind": zone.kind.value,
        "floor_m": zone.floor_m,
        "ceiling_m": zone.ceiling_m,
        "amsl": zone.altitude_ref == AltitudeRef.amsl,
        "source": "base" if zone.base_id else "zone",
    }
    if g["type"] == "Point":
        lon, lat = g["coordinates"][0], g["coordinates"][1]
        return ZoneShape(center=(lat, lon), radius_m=float(zone.radius_m or 0.0), **common)
    ring = tuple((float(p[0]), float(p[1])) for p in g["coordinates"][0])
    return ZoneShape(ring=ring, **common)
