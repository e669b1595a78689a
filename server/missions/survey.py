"""Survey areas compiled into a lawnmower (boustrophedon) path of mission items. Pure functions."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from server.missions.geometry import LocalProjection, Point, open_ring, rotate, scanline
from server.missions.items import (
    DO_CHANGE_SPEED,
    DO_SET_CAM_TRIGG_DIST,
    FRAME_GLOBAL_RELATIVE_ALT,
    FRAME_MISSION,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionItem,
)

MAX_LINES = 5000  # far beyond any mission a UAV can store; guards against absurd spacing


@dataclass(frozen=True)
class Camera:
    """A camera: sensor size, focal length and image size."""

    sensor_width_mm: float
    sensor_height_mm: float
    focal_length_mm: float
    image_width_px: int
    image_height_px: int

    def footprint(self, altitude_m: float) -> tuple[float, float]:
        """Ground footprint (across track, along track) in metres of a nadir image at `altitude_m`.

        The image's width lies across the flight line (landscape, as QGroundControl plans it).
        """
        return (
            altitude_m * self.sensor_width_mm / self.focal_length_mm,
            altitude_m * self.sensor_height_mm / self.focal_length_mm,
        )

    def gsd_cm(self, altitude_m: float) -> float:
        """Ground sampling distance in centimetres per pixel at `altitude_m`."""
        return 100.0 * self.footprint(altitude_m)[0] / self.image_width_px


@dataclass(frozen=True)
class SurveySpec:
    """What a survey needs: the area (lon/lat ring), the footprint, overlaps, altitude, speed."""

    ring: tuple[Point, ...]  # (lon, lat) as GeoJSON
    footprint_across_m: float
    footprint_along_m: float
    front_overlap_pct: float
    side_overlap_pct: float
    altitude_m: float
    speed_mps: float
    heading_deg: float | None = None  # direction of the lines, clockwise from north; None: best
    takeoff: tuple[float, float] | None = None  # (lat, lon) of the takeoff; None: first waypoint
    camera_trigger: bool = True  # DO_SET_CAM_TRIGG_DIST on each line (off: waypoints only)

    @property
    def line_spacing_m(self) -> float:
        """Distance between neighbouring lines."""
        return self.footprint_across_m * (1.0 - self.side_overlap_pct / 100.0)

    @property
    def trigger_distance_m(self) -> float:
        """Distance flown between two photos."""
        return self.footprint_along_m * (1.0 - self.front_overlap_pct / 100.0)


@dataclass(frozen=True)
class SurveyPlan:
    """A compiled survey: its lines (lat, lon pairs), the heading used and the mission items."""

    heading_deg: float
    lines: tuple[tuple[tuple[float, float], tuple[float, float]], ...]
    items: tuple[MissionItem, ...]
    line_spacing_m: float
    trigger_distance_m: float


def _local_ring(spec: SurveySpec) -> tuple[LocalProjection, list[Point]]:
    pts = open_ring(spec.ring)
    lon0 = sum(p[0] for p in pts) / len(pts)
    lat0 = sum(p[1] for p in pts) / len(pts)
    proj = LocalProjection(lat0, lon0)
    return proj, [proj.to_local(lat, lon) for lon, lat in pts]


def line_count(local: Sequence[Point], heading_deg: float, spacing: float) -> int:
    """How many lines cover the ring when flown along `heading_deg` with `spacing`."""
    ys = [_turn(p, heading_deg)[1] for p in local]
    width = max(ys) - min(ys)
    return max(1, math.ceil(width / spacing - 1e-9))


def best_heading(local: Sequence[Point], spacing: float) -> float:
    """The heading along one of the polygon's edges that needs the fewest lines."""
    best: tuple[int, float] | None = None
    for i, (x1, y1) in enumerate(local):
        x2, y2 = local[(i + 1) % len(local)]
        if (x1, y1) == (x2, y2):
            continue
        heading = math.degrees(math.atan2(x2 - x1, y2 - y1)) % 180.0
        candidate = (line_count(local, heading, spacing), round(heading, 6))
        if best is None or candidate < best:
            best = candidate
    return best[1] if best else 0.0


def lawnmower(
    local: Sequence[Point], heading_deg: float, spacing: float
) -> list[tuple[Point, Point]]:
    """Boustrophedon segments (start, end) in local metres, lines clipped to the ring.

    Lines run along `heading_deg`, `spacing` apart, centred on the area so the outer footprints
    reach its edges; consecutive segments alternate direction. A concave area can cut a line
    into several spans; each span becomes a segment.
    """
    turned = [_turn(p, heading_deg) for p in local]  # lines become horizontal
    ys = [p[1] for p in turned]
    lo, hi = min(ys), max(ys)
    n = max(1, math.ceil((hi - lo) / spacing - 1e-9))
    if n > MAX_LINES:
        raise ValueError(f"{n} lines needed, more than {MAX_LINES}")
    first = lo + ((hi - lo) - (n - 1) * spacing) / 2.0
    out: list[tuple[Point, Point]] = []
    forward = True
    for k in range(n):
        y = first + k * spacing
        spans = scanline(turned, y)
        if not forward:
            spans = [(b, a) for a, b in reversed(spans)]
        for x_from, x_to in spans:
            out.append((_unturn((x_from, y), heading_deg), _unturn((x_to, y), heading_deg)))
        if spans:
            forward = not forward
    return out


def _turn(p: Point, heading_deg: float) -> Point:
    """Rotate local metres so that `heading_deg` (clockwise from north) points along +x."""
    return rotate(p, math.radians(heading_deg) - math.pi / 2)


def _unturn(p: Point, heading_deg: float) -> Point:
    return rotate(p, math.pi / 2 - math.radians(heading_deg))


def compile_survey(spec: SurveySpec) -> SurveyPlan:
    """The lawnmower path of a survey as mission items.

    takeoff → change speed → for each segment: waypoint, camera trigger every
    `trigger_distance_m`, waypoint, trigger off → return to launch.
    """
    proj, local = _local_ring(spec)
    spacing = spec.line_spacing_m
    heading = (
        spec.heading_deg % 180.0 if spec.heading_deg is not None else best_heading(local, spacing)
    )
    segments = lawnmower(local, heading, spacing)
    lines = tuple((_geo(proj, a), _geo(proj, b)) for a, b in segments)
    alt = spec.altitude_m
    first = lines[0][0] if lines else (proj.lat0, proj.lon0)
    takeoff = spec.takeoff or first
    items = [
        MissionItem(
            command=NAV_TAKEOFF,
            frame=FRAME_GLOBAL_RELATIVE_ALT,
            params=(0, 0, 0, None),
            lat=takeoff[0],
            lon=takeoff[1],
            alt=alt,
        ),
        MissionItem(
            command=DO_CHANGE_SPEED, frame=FRAME_MISSION, params=(1, spec.speed_mps, -1, 0)
        ),
    ]
    trigger = round(spec.trigger_distance_m, 3)
    for start, end in lines:
        items.append(_waypoint(start, alt))
        if spec.camera_trigger:
            items.append(
                MissionItem(
                    command=DO_SET_CAM_TRIGG_DIST, frame=FRAME_MISSION, params=(trigger, 0, 1, 0)
                )
            )
        items.append(_waypoint(end, alt))
        if spec.camera_trigger:
            items.append(
                MissionItem(command=DO_SET_CAM_TRIGG_DIST, frame=FRAME_MISSION, params=(0, 0, 0, 0))
            )
    items.append(MissionItem(command=NAV_RETURN_TO_LAUNCH, frame=FRAME_MISSION))
    return SurveyPlan(
        heading_deg=heading,
        lines=lines,
        items=tuple(items),
        line_spacing_m=spacing,
        trigger_distance_m=spec.trigger_distance_m,
    )


def _geo(proj: LocalProjection, p: Point) -> tuple[float, float]:
    lat, lon = proj.to_geo(*p)
    return round(lat, 7), round(lon, 7)


def _waypoint(latlon: tuple[float, float], alt: float) -> MissionItem:
    return MissionItem(
        command=NAV_WAYPOINT,
        frame=FRAME_GLOBAL_RELATIVE_ALT,
        params=(0, 0, 0, None),
        lat=latlon[0],
        lon=latlon[1],
        alt=alt,
    )
