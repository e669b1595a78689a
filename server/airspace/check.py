"""A mission's flight path checked against airspace zones, in metres. Pure functions.

Geometry runs in a local east/north projection around the launch point (the base): the
equirectangular `LocalProjection` of server/missions/geometry.py, whose error against the
ellipsoid stays under 0.1 % over the few kilometres a mission from a base spans (a 5 km
leg is off by less than 5 m), well inside the margins zones are drawn with.

The path is what the UAV flies, not its waypoints: the climb from the base, every straight
segment between positional navigation items (so the lanes of a compiled survey), the leg
back to the base for RTL or a mission that ends without LAND/RTL, and the final descent.

Rules (the ones ArduPilot's fence applies on board, so the check and the autopilot agree):
- an inclusion zone must contain the whole path, up to its ceiling; when several inclusion
  zones apply the path must stay inside every one of them (AC_PolyFence: "inside all");
- an exclusion zone must not be entered between its floor and its ceiling (no floor: from
  the ground; no ceiling: without limit).
Altitudes are metres above the launch point unless a zone says `amsl`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from server.missions.geometry import LocalProjection, open_ring
from server.missions.items import (
    NAV_LAND,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
)
from server.missions.validate import Home, relative_alt

Vec = tuple[float, float]
EPS_M = 0.05  # how much of a segment may graze a boundary (rounding, a vertex on an edge)


@dataclass(frozen=True)
class ZoneShape:
    """A zone as the check sees it: a polygon ring of (lon, lat) or a circle, and its band."""

    id: str
    name: str
    kind: Literal["inclusion", "exclusion"]
    ring: tuple[tuple[float, float], ...] = ()  # (lon, lat), open or closed
    center: tuple[float, float] | None = None  # (lat, lon)
    radius_m: float = 0.0
    floor_m: float | None = None
    ceiling_m: float | None = None
    amsl: bool = False  # floor/ceiling in metres above mean sea level, not above the base
    source: str = "zone"  # zone | base | plan (a QGroundControl geoFence item)


@dataclass(frozen=True)
class Segment:
    """A straight piece of the path between two points, named by the items at its ends."""

    start: str  # "home" or "items[i]"
    end: str
    a: tuple[float, float, float]  # east, north, up (metres, up above the launch point)
    b: tuple[float, float, float]
    leg: str  # climb | cruise | return | descent
    index: int | None  # the item the segment flies to (None: the base)

    @property
    def label(self) -> str:
        """How a problem names the segment."""
        extra = {"return": " (the return leg to the base)", "climb": " (the take-off climb)"}
        return f"{self.start}→{self.end}{extra.get(self.leg, '')}"


@dataclass(frozen=True)
class AirspaceProblem:
    """One way the path breaks a zone: which segment, which zone, by how many metres."""

    where: str
    what: str
    value: float
    limit: float
    segment: list[str]
    zone: dict[str, Any]
    index: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON shape, the one mission problems have plus `segment` and `zone`."""
        d: dict[str, Any] = {
            "where": self.where,
            "what": self.what,
            "value": self.value,
            "limit": self.limit,
            "segment": self.segment,
            "zone": self.zone,
            "code": "airspace",
        }
        if self.index is not None:
            d["index"] = self.index
        return d


def _positional(item: MissionItem) -> bool:
    spec = item.spec
    return bool(spec and spec.nav and spec.positional and (item.lat, item.lon) != (0.0, 0.0))


def flight_path(
    items: Sequence[MissionItem], home: Home | None, proj: LocalProjection
) -> list[Segment]:
    """The straight segments the UAV flies: climb, items in order, return leg, descent.

    DO_JUMP loops fly the same segments again, plus one from the jump back to its target;
    that closing segment is added once.
    """
    segs: list[Segment] = []
    if home is None:
        first = next((i for i in items if _positional(i)), None)
        if first is None:
            return []
        home = Home(first.lat, first.lon, 0.0)
    base = (*proj.to_local(home.lat, home.lon), 0.0)
    pos, name = base, "home"
    positions: dict[int, tuple[tuple[float, float, float], str]] = {}
    landed = False
    for i, item in enumerate(items):
        rel = relative_alt(item, home)
        alt = pos[2] if rel is None else rel
        here = f"items[{i}]"
        if item.command == NAV_TAKEOFF:
            to = (pos[0], pos[1], alt)
            segs.append(Segment(name, here, pos, to, "climb", i))
        elif item.command == NAV_RETURN_TO_LAUNCH:
            above = (base[0], base[1], pos[2])
            segs.append(Segment(name, "home", pos, above, "return", None))
            segs.append(Segment("home", "home", above, base, "descent", None))
            landed = True
            break
        elif item.command == NAV_LAND:
            xy = proj.to_local(item.lat, item.lon) if _positional(item) else pos[:2]
            above = (xy[0], xy[1], pos[2])
            segs.append(Segment(name, here, pos, above, "cruise", i))
            segs.append(Segment(here, here, above, (xy[0], xy[1], 0.0), "descent", i))
            landed = True
            break
        elif _positional(item):
            x, y = proj.to_local(item.lat, item.lon)
            to = (x, y, alt)
            segs.append(Segment(name, here, pos, to, "cruise", i))
            positions[i] = (to, here)
        elif item.command == 177:  # DO_JUMP: param1 is the target's seq (index + 1)
            target = item.params[0]
            if target is not None and int(target) - 1 in positions:
                to, there = positions[int(target) - 1]
                segs.append(Segment(name, there, pos, to, "cruise", int(target) - 1))
            continue
        else:
            continue
        pos, name = segs[-1].b, segs[-1].end
    if not landed:
        above = (base[0], base[1], pos[2])
        segs.append(Segment(name, "home", pos, above, "return", None))
        segs.append(Segment("home", "home", above, base, "descent", None))
    return [s for s in segs if s.a != s.b]


# --- the length of a segment inside a shape ------------------------------------------


def _inside_ring(p: Vec, ring: Sequence[Vec]) -> bool:
    x, y = p
    inside = False
    n = len(ring)
    for k in range(n):
        (x1, y1), (x2, y2) = ring[k], ring[(k + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _cuts(a: Vec, b: Vec, ring: Sequence[Vec]) -> list[float]:
    """Parameters t in (0, 1) where segment a→b crosses an edge of the ring."""
    out = []
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = len(ring)
    for k in range(n):
        (x1, y1), (x2, y2) = ring[k], ring[(k + 1) % n]
        ex, ey = x2 - x1, y2 - y1
        den = dx * ey - dy * ex
        if den == 0:
            continue
        t = ((x1 - a[0]) * ey - (y1 - a[1]) * ex) / den
        u = ((x1 - a[0]) * dy - (y1 - a[1]) * dx) / den
        if 0 < t < 1 and 0 <= u <= 1:
            out.append(t)
    return out


def _circle_cuts(a: Vec, b: Vec, c: Vec, r: float) -> list[float]:
    dx, dy = b[0] - a[0], b[1] - a[1]
    fx, fy = a[0] - c[0], a[1] - c[1]
    qa, qb, qc = dx * dx + dy * dy, 2 * (fx * dx + fy * dy), fx * fx + fy * fy - r * r
    disc = qb * qb - 4 * qa * qc
    if qa == 0 or disc <= 0:
        return []
    root = math.sqrt(disc)
    return [t for t in ((-qb - root) / (2 * qa), (-qb + root) / (2 * qa)) if 0 < t < 1]


@dataclass(frozen=True)
class LocalZone:
    """A zone in local metres: inside a point, and a segment split at its boundary."""

    zone: ZoneShape
    ring: tuple[Vec, ...] = ()
    center: Vec | None = None

    def inside(self, p: Vec) -> bool:
        """True when `p` is in the zone (on a circle's edge counts as in)."""
        if self.center is not None:
            return math.dist(p, self.center) <= self.zone.radius_m
        return _inside_ring(p, self.ring)

    def pieces(self, a: Vec, b: Vec) -> list[tuple[float, float, bool]]:
        """The segment split at the boundary: (t0, t1, inside) pieces."""
        ts = (
            _circle_cuts(a, b, self.center, self.zone.radius_m)
            if self.center is not None
            else _cuts(a, b, self.ring)
        )
        cuts = [0.0, *sorted(ts), 1.0]
        out = []
        for t0, t1 in itertools.pairwise(cuts):
            if t1 - t0 <= 0:
                continue
            tm = (t0 + t1) / 2
            mid = (a[0] + (b[0] - a[0]) * tm, a[1] + (b[1] - a[1]) * tm)
            out.append((t0, t1, self.inside(mid)))
        return out


def localise(zone: ZoneShape, proj: LocalProjection) -> LocalZone:
    """The zone in the projection's metres."""
    if zone.center is not None:
        return LocalZone(zone, center=proj.to_local(*zone.center))
    return LocalZone(zone, ring=tuple(proj.to_local(lat, lon) for lon, lat in open_ring(zone.ring)))


def _band(zone: ZoneShape, home: Home | None) -> tuple[float, float]:
    """The zone's floor and ceiling in metres above the launch point."""
    shift = (home.alt if home else 0.0) if zone.amsl else 0.0
    floor = -math.inf if zone.floor_m is None else zone.floor_m - shift
    ceiling = math.inf if zone.ceiling_m is None else zone.ceiling_m - shift
    return floor, ceiling


def _zone_ref(zone: ZoneShape) -> dict[str, Any]:
    return {"id": zone.id, "name": zone.name, "kind": zone.kind, "source": zone.source}


def _z_range(seg: Segment, t0: float, t1: float) -> tuple[float, float]:
    z0 = seg.a[2] + (seg.b[2] - seg.a[2]) * t0
    z1 = seg.a[2] + (seg.b[2] - seg.a[2]) * t1
    return min(z0, z1), max(z0, z1)


def check_path(
    items: Sequence[MissionItem], home: Home | None, zones: Sequence[ZoneShape]
) -> list[AirspaceProblem]:
    """Every segment of the path that leaves an inclusion zone, enters an exclusion zone or
    climbs above a ceiling, with the zone and the metres by which it does."""
    if not zones:
        return []
    origin = home or next(
        (Home(i.lat, i.lon) for i in items if _positional(i)), Home(0.0, 0.0, 0.0)
    )
    proj = LocalProjection(origin.lat, origin.lon)
    path = flight_path(items, home, proj)
    problems: list[AirspaceProblem] = []
    for zone in zones:
        local = localise(zone, proj)
        floor, ceiling = _band(zone, home)
        for seg in path:
            a, b = seg.a[:2], seg.b[:2]
            horizontal = math.dist(a, b)
            pieces = local.pieces(a, b) if horizontal > 0 else [(0.0, 1.0, local.inside(a))]
            problems += _judge(zone, seg, pieces, horizontal, floor, ceiling)
    return problems


def _judge(
    zone: ZoneShape,
    seg: Segment,
    pieces: list[tuple[float, float, bool]],
    horizontal: float,
    floor: float,
    ceiling: float,
) -> list[AirspaceProblem]:
    ref, span = _zone_ref(zone), [seg.start, seg.end]
    label = f"zone {zone.name!r}" if zone.source != "plan" else f"the plan's fence {zone.name}"
    out: list[AirspaceProblem] = []
    if zone.kind == "exclusion":
        length, worst = 0.0, None
        for t0, t1, inside in pieces:
            lo, hi = _z_range(seg, t0, t1)
            if inside and hi > floor and lo < ceiling:
                length += (t1 - t0) * horizontal
                worst = worst or (t0, t1)
        if worst is not None and (length > EPS_M or horizontal == 0):
            out.append(
                AirspaceProblem(
                    "path",
                    f"segment {seg.label} enters exclusion {label} for {length:.1f} m",
                    round(length, 1),
                    0.0,
                    span,
                    ref,
                    seg.index,
                )
            )
        return out
    outside = sum((t1 - t0) * horizontal for t0, t1, inside in pieces if not inside)
    if outside > EPS_M or (horizontal == 0 and not pieces[0][2]):
        out.append(
            AirspaceProblem(
                "path",
                f"segment {seg.label} leaves inclusion {label} for {outside:.1f} m",
                round(outside, 1),
                0.0,
                span,
                ref,
                seg.index,
            )
        )
    top = max(seg.a[2], seg.b[2])
    if top > ceiling + EPS_M:
        out.append(
            AirspaceProblem(
                "path",
                f"segment {seg.label} climbs {top - ceiling:.1f} m above the ceiling of "
                f"{label} ({ceiling:.1f} m above the base)",
                round(top - ceiling, 1),
                round(ceiling, 1),
                span,
                ref,
                seg.index,
            )
        )
    bottom = min(seg.a[2], seg.b[2])
    if seg.leg == "cruise" and bottom < floor - EPS_M:
        out.append(
            AirspaceProblem(
                "path",
                f"segment {seg.label} flies {floor - bottom:.1f} m below the floor of {label}",
                round(floor - bottom, 1),
                round(floor, 1),
                span,
                ref,
                seg.index,
            )
        )
    return out
