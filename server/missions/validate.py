"""Mission validation: one `Problem` per fault (where, what, value, limit). Pure functions."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

from server.missions.geometry import (
    LocalProjection,
    Point,
    distinct_points,
    open_ring,
    ring_area,
    self_intersections,
)
from server.missions.items import (
    COMMANDS,
    DO_CHANGE_SPEED,
    DO_JUMP,
    FRAME_GLOBAL,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_TURNS,
    NAV_RETURN_TO_LAUNCH,
    NAV_WAYPOINT,
    MissionItem,
    command_name,
    frame_problem,
    normalize_frame,
)


@dataclass(frozen=True)
class Problem:
    """One reason a mission cannot be taken: where, what, the offending value and the limit."""

    where: str
    what: str
    value: Any = None
    limit: Any = None
    index: int | None = None
    command: int | None = None
    code: str | None = None  # for the checks a run's creation refuses on (out_of_reach, ...)

    def as_dict(self) -> dict[str, Any]:
        """JSON shape: where, what, value, limit, plus index, command and code when they apply."""
        d = asdict(self)
        for key in ("index", "command", "code"):
            if d[key] is None:
                del d[key]
        return d


@dataclass(frozen=True)
class MissionLimits:
    """Configurable limits (defaults: 2..120 m relative altitude, 4 km² survey area)."""

    min_alt_m: float = 2.0
    max_alt_m: float = 120.0
    max_area_m2: float = 4_000_000.0
    max_items: int = 1000
    max_speed_mps: float = 25.0
    min_line_spacing_m: float = 1.0


@dataclass(frozen=True)
class Home:
    """Home position: lat, lon in degrees, alt in metres above mean sea level."""

    lat: float
    lon: float
    alt: float = 0.0


def check_latlon(where: str, lat: float, lon: float) -> list[Problem]:
    """Latitude in [-90, 90], longitude in [-180, 180]."""
    out = []
    if not -90.0 <= lat <= 90.0:
        out.append(Problem(f"{where}.lat", "latitude out of range", lat, [-90, 90]))
    if not -180.0 <= lon <= 180.0:
        out.append(Problem(f"{where}.lon", "longitude out of range", lon, [-180, 180]))
    return out


def relative_alt(item: MissionItem, home: Home | None) -> float | None:
    """Height above home of an item (None when its frame is AMSL and home is unknown)."""
    frame = normalize_frame(item.frame)
    if frame == FRAME_GLOBAL:
        return None if home is None else item.alt - home.alt
    return item.alt


def validate_items(
    items: Sequence[MissionItem],
    limits: MissionLimits,
    home: Home | None = None,
    where: str = "items",
) -> list[Problem]:
    """Every problem of a list of items: commands, frames, coordinates, altitudes, jumps, speeds."""
    problems: list[Problem] = []
    if not items:
        problems.append(Problem(where, "a mission needs at least one item", 0, 1))
    if len(items) > limits.max_items:
        problems.append(Problem(where, "too many items", len(items), limits.max_items))
    if home is not None:
        problems += check_latlon("home", home.lat, home.lon)
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        spec = COMMANDS.get(item.command)
        if spec is None:
            problems.append(
                Problem(
                    f"{at}.command",
                    f"unsupported command {command_name(item.command)}",
                    item.command,
                    sorted(COMMANDS),
                    index=i,
                    command=item.command,
                )
            )
            continue
        why = frame_problem(item.command, item.frame)
        if why:
            problems.append(Problem(f"{at}.frame", why, item.frame, index=i, command=item.command))
        if spec.positional:
            problems += [_at(p, i, item.command) for p in check_latlon(at, item.lat, item.lon)]
        if spec.nav and spec.positional and item.command != NAV_LAND:
            rel = relative_alt(item, home)
            if rel is not None and not limits.min_alt_m <= rel <= limits.max_alt_m:
                what = (
                    "altitude below the minimum"
                    if rel < limits.min_alt_m
                    else "altitude above the maximum"
                )
                limit = limits.min_alt_m if rel < limits.min_alt_m else limits.max_alt_m
                problems.append(
                    Problem(
                        f"{at}.alt",
                        f"{what} (metres above home)",
                        round(rel, 3),
                        limit,
                        index=i,
                        command=item.command,
                    )
                )
        problems += _param_problems(i, at, item, len(items), limits)
    return problems


def _at(p: Problem, index: int, command: int) -> Problem:
    return Problem(p.where, p.what, p.value, p.limit, index=index, command=command)


def _param_problems(
    i: int, at: str, item: MissionItem, count: int, limits: MissionLimits
) -> list[Problem]:
    p1, p2 = item.params[0], item.params[1]
    out = []
    if item.command == DO_JUMP:
        # param1 is a MAVLink seq: items are seq 1..count (seq 0 is home)
        if p1 is None or p1 != int(p1) or not 1 <= p1 <= count:
            out.append(
                Problem(
                    f"{at}.params[0]",
                    "DO_JUMP target is not an item of this mission (seq = index + 1)",
                    p1,
                    [1, count],
                    index=i,
                    command=item.command,
                )
            )
        if p2 is None or p2 != int(p2) or p2 < -1:
            out.append(
                Problem(
                    f"{at}.params[1]",
                    "DO_JUMP repeat count must be a whole number >= -1",
                    p2,
                    -1,
                    index=i,
                    command=item.command,
                )
            )
    elif item.command == DO_CHANGE_SPEED:
        if p2 is None or not 0 < p2 <= limits.max_speed_mps:
            out.append(
                Problem(
                    f"{at}.params[1]",
                    "speed out of range (m/s)",
                    p2,
                    limits.max_speed_mps,
                    index=i,
                    command=item.command,
                )
            )
    elif item.command in (NAV_LOITER_TIME, NAV_WAYPOINT) and p1 is not None and p1 < 0:
        what = (
            "loiter time must be >= 0 s"
            if item.command == NAV_LOITER_TIME
            else "hold time must be >= 0 s"
        )
        out.append(Problem(f"{at}.params[0]", what, p1, 0, index=i, command=item.command))
    elif item.command == NAV_LOITER_TIME and p1 is None:
        out.append(
            Problem(
                f"{at}.params[0]",
                "loiter time must be >= 0 s",
                p1,
                0,
                index=i,
                command=item.command,
            )
        )
    elif item.command == NAV_LOITER_TURNS and (p1 is None or p1 <= 0):
        out.append(
            Problem(
                f"{at}.params[0]", "loiter turns must be > 0", p1, 0, index=i, command=item.command
            )
        )
    return out


def validate_ring(
    ring: Sequence[Point], limits: MissionLimits, where: str = "survey.polygon"
) -> list[Problem]:
    """A survey area (lon, lat ring): not empty, 3+ distinct points, in range, simple, small enough."""
    pts = open_ring(ring)
    if not pts:
        return [Problem(where, "the polygon is empty", 0, 3)]
    problems: list[Problem] = []
    for k, (lon, lat) in enumerate(pts):
        problems += check_latlon(f"{where}.coordinates[0][{k}]", lat, lon)
    if problems:
        return problems
    n = distinct_points(pts)
    if n < 3:
        return [Problem(where, "a polygon needs at least 3 distinct points", n, 3)]
    proj = LocalProjection(sum(p[1] for p in pts) / len(pts), sum(p[0] for p in pts) / len(pts))
    local = [proj.to_local(lat, lon) for lon, lat in pts]
    for i, j in self_intersections(local):
        problems.append(
            Problem(where, f"the polygon intersects itself: edge {i} meets edge {j}", [i, j])
        )
    area = abs(ring_area(local))
    if area > limits.max_area_m2:
        problems.append(
            Problem(where, "the area is too large (m²)", round(area, 1), limits.max_area_m2)
        )
    elif area < 1.0 and not problems:
        problems.append(Problem(where, "the polygon has no area (m²)", round(area, 3), 1.0))
    return problems


@dataclass(frozen=True)
class FlightModel:
    """How long flying takes: vertical speeds and fixed overheads (ArduPilot Copter defaults)."""

    climb_mps: float = 2.5  # WPNAV_SPEED_UP
    descent_mps: float = 1.5  # WPNAV_SPEED_DN
    per_waypoint_s: float = 3.0  # slowing down and speeding up at each waypoint
    takeoff_s: float = 10.0  # arming, spool-up, settling
    landing_s: float = 30.0  # final slow descent and precision landing
    loiter_radius_m: float = 10.0  # when a loiter item gives none
    max_steps: int = 100_000  # bounds the walk through DO_JUMP loops


@dataclass(frozen=True)
class FlightEstimate:
    """Path length and flight time of a mission; `endless` when it never ends by itself."""

    distance_m: float
    flight_time_s: float
    endless: bool = False
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        """JSON shape."""
        return {
            "distance_m": round(self.distance_m, 1),
            "flight_time_s": round(self.flight_time_s, 1),
            "endless": self.endless,
            "note": self.note,
        }


def check_endurance(
    estimate: FlightEstimate, endurance_s: float, reserve: float = 0.2
) -> list[Problem]:
    """The estimated flight time against the UAV's endurance minus a reserve."""
    usable = endurance_s * (1.0 - reserve)
    if estimate.endless:
        return [
            Problem(
                "mission",
                f"the mission never ends by itself ({estimate.note})",
                None,
                round(usable, 1),
            )
        ]
    if estimate.flight_time_s > usable:
        return [
            Problem(
                "mission",
                f"estimated flight time (s) exceeds the UAV's endurance less a "
                f"{reserve:.0%} reserve",
                round(estimate.flight_time_s, 1),
                round(usable, 1),
                code="endurance",
            )
        ]
    return []


def is_landing(item: MissionItem) -> bool:
    """True for the items that end a flight (land, return to launch)."""
    return item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH)


def finite(v: float) -> bool:
    """True for a finite float."""
    return math.isfinite(v)
