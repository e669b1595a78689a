"""Building a mission from what was asked: items checked, or a survey area compiled. Pure functions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from server.missions.geometry import LocalProjection, open_ring, ring_area
from server.missions.items import MissionItem
from server.missions.models import MissionKind
from server.missions.schemas import HomeIn, SurveyIn
from server.missions.survey import Camera, SurveySpec, compile_survey
from server.missions.validate import Home, MissionLimits, Problem, validate_items, validate_ring


@dataclass(frozen=True)
class Built:
    """A mission's items and, for a survey, the compiled figures."""

    items: list[MissionItem]
    survey_plan: dict[str, Any] | None = None


DO_CHANGE_SPEED, NAV_TAKEOFF = 178, 22
SPEED_TYPE_GROUND, THROTTLE_UNCHANGED = 1.0, -1.0
MAV_CMD_FIRST_NON_NAV = 100  # MAV_CMD_NAV_* are below 100; CONDITION_* and DO_* above


def flight_items(items: list[dict[str, Any]], speed_mps: float | None) -> list[dict[str, Any]]:
    """The items the UAV is sent: the mission's, with its speed as a DO_CHANGE_SPEED item.

    Without the item an autopilot flies its own default (ArduPilot's WPNAV_SPEED, 10 m/s), not
    the plan's cruise/hover speed. The item goes right after a leading take-off (ArduPilot runs
    the DO commands that follow a NAV command while that one flies, so the speed holds from
    the first waypoint on), else first. A mission that sets its speed before its first
    waypoint already, or that has no speed, is sent as it is.
    """
    if not speed_mps or speed_mps <= 0:
        return list(items)
    start = 1 if items and items[0].get("command") == NAV_TAKEOFF else 0
    for item in items[start:]:
        if item.get("command") == DO_CHANGE_SPEED:
            return list(items)
        if int(item.get("command") or 0) < MAV_CMD_FIRST_NON_NAV:  # a NAV command: flying
            break
    speed = {
        "command": DO_CHANGE_SPEED,
        "frame": 2,  # MAV_FRAME_MISSION: no position
        "params": [SPEED_TYPE_GROUND, float(speed_mps), THROTTLE_UNCHANGED, 0.0],
        "lat": 0.0,
        "lon": 0.0,
        "alt": 0.0,
        "autocontinue": True,
    }
    return [*items[:start], speed, *items[start:]]


def home_of(home: HomeIn | dict[str, Any] | None) -> Home | None:
    """The domain value of a home position."""
    if home is None:
        return None
    h = home.model_dump() if isinstance(home, HomeIn) else home
    return Home(float(h["lat"]), float(h["lon"]), float(h.get("alt", 0.0)))


def build(
    kind: MissionKind,
    items: list[MissionItem] | None,
    survey: SurveyIn | None,
    home: Home | None,
    limits: MissionLimits,
) -> tuple[Built, list[Problem]]:
    """The mission's final items, and every problem found on the way."""
    if kind == MissionKind.waypoints:
        problems = []
        if survey is not None:
            problems.append(Problem("survey", "a waypoints mission takes items, not a survey"))
        normalized = [i.normalized() for i in items or []]
        problems += validate_items(normalized, limits, home)
        return Built(normalized), problems
    return _build_survey(items, survey, home, limits)


def _build_survey(
    items: list[MissionItem] | None,
    survey: SurveyIn | None,
    home: Home | None,
    limits: MissionLimits,
) -> tuple[Built, list[Problem]]:
    if survey is None:
        return Built([]), [Problem("survey", "a survey mission needs a survey area and parameters")]
    problems: list[Problem] = []
    if items:
        problems.append(
            Problem(
                "items",
                "a survey's items are compiled from its area; do not give them",
                len(items),
                0,
            )
        )
    rings = survey.polygon.coordinates
    if len(rings) > 1:
        problems.append(
            Problem(
                "survey.polygon.coordinates",
                "holes (inner rings) are not supported",
                len(rings) - 1,
                0,
            )
        )
    ring = rings[0] if rings else []
    bad = [k for k, pos in enumerate(ring) if len(pos) not in (2, 3)]
    if bad:
        problems.append(
            Problem(
                f"survey.polygon.coordinates[0][{bad[0]}]",
                "a position is [lon, lat] or [lon, lat, alt]",
                len(ring[bad[0]]),
                2,
            )
        )
        return Built([]), problems
    points = tuple((p[0], p[1]) for p in ring)
    problems += validate_ring(points, limits)
    alt = survey.altitude_m
    if not limits.min_alt_m <= alt <= limits.max_alt_m:
        problems.append(
            Problem(
                "survey.altitude_m",
                "altitude out of range (metres above home)",
                alt,
                [limits.min_alt_m, limits.max_alt_m],
            )
        )
    if (survey.camera is None) == (survey.footprint is None):
        problems.append(
            Problem("survey", "give either a camera or a ground footprint (one of them)")
        )
    if problems:
        return Built([]), problems
    camera = None
    if survey.camera is not None:
        camera = Camera(**survey.camera.model_dump())
        width, height = camera.footprint(alt)
    else:
        assert survey.footprint is not None
        width, height = survey.footprint.width_m, survey.footprint.height_m
    spec = SurveySpec(
        ring=points,
        footprint_across_m=width,
        footprint_along_m=height,
        front_overlap_pct=survey.front_overlap_pct,
        side_overlap_pct=survey.side_overlap_pct,
        altitude_m=alt,
        speed_mps=survey.speed_mps,
        heading_deg=survey.heading_deg,
        takeoff=(home.lat, home.lon) if home else None,
        camera_trigger=survey.camera_trigger,
    )
    if spec.line_spacing_m < limits.min_line_spacing_m:
        return Built([]), [
            Problem(
                "survey",
                "line spacing too small (m): raise the altitude or lower the side overlap",
                round(spec.line_spacing_m, 3),
                limits.min_line_spacing_m,
            )
        ]
    try:
        plan = compile_survey(spec)
    except ValueError as err:
        return Built([]), [Problem("survey", f"cannot compile the survey: {err}")]
    compiled = list(plan.items)
    problems += validate_items(compiled, limits, home)
    pts = open_ring(points)
    proj = LocalProjection(sum(p[1] for p in pts) / len(pts), sum(p[0] for p in pts) / len(pts))
    area = abs(ring_area([proj.to_local(lat, lon) for lon, lat in pts]))
    figures = {
        "heading_deg": round(plan.heading_deg, 3),
        "line_count": len(plan.lines),
        "line_spacing_m": round(plan.line_spacing_m, 3),
        "trigger_distance_m": round(plan.trigger_distance_m, 3),
        "footprint_width_m": round(width, 3),
        "footprint_height_m": round(height, 3),
        "gsd_cm": round(camera.gsd_cm(alt), 3) if camera else None,
        "area_m2": round(area, 1),
    }
    return Built(compiled, figures), problems
