"""Path length and flight time of a mission, walking its items as ArduPilot Copter flies them."""

from __future__ import annotations

import math
from collections.abc import Sequence

from server.missions.geometry import haversine_m
from server.missions.items import (
    CONDITION_DELAY,
    DO_CHANGE_SPEED,
    DO_JUMP,
    NAV_DELAY,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_TURNS,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
)
from server.missions.validate import FlightEstimate, FlightModel, Home, relative_alt


class _Walk:
    """Position, altitude and speed of the vehicle while the items are walked."""

    def __init__(self, start: tuple[float, float], speed: float, model: FlightModel) -> None:
        self.start = start
        self.pos = start
        self.alt = 0.0
        self.speed = speed
        self.model = model
        self.distance = 0.0
        self.time = 0.0

    def fly_to(self, lat: float, lon: float, alt: float | None) -> None:
        """Fly straight to a point (alt None: keep the altitude); climb and cruise overlap."""
        horizontal = haversine_m(self.pos[0], self.pos[1], lat, lon)
        target = self.alt if alt is None else alt
        climb = target - self.alt
        vertical_t = climb / self.model.climb_mps if climb > 0 else -climb / self.model.descent_mps
        self.distance += math.hypot(horizontal, climb)
        self.time += max(horizontal / self.speed, vertical_t) + self.model.per_waypoint_s
        self.pos, self.alt = (lat, lon), target

    def land_here(self) -> None:
        """Descend to the ground where the vehicle is, then land."""
        self.distance += self.alt
        self.time += self.alt / self.model.descent_mps + self.model.landing_s
        self.alt = 0.0


def _start(items: Sequence[MissionItem], home: Home | None) -> tuple[float, float]:
    if home is not None:
        return home.lat, home.lon
    for item in items:
        if (
            item.spec
            and item.spec.nav
            and item.spec.positional
            and (item.lat, item.lon) != (0.0, 0.0)
        ):
            return item.lat, item.lon
    return 0.0, 0.0


def estimate_flight(
    items: Sequence[MissionItem],
    speed_mps: float,
    home: Home | None = None,
    model: FlightModel | None = None,
) -> FlightEstimate:
    """Distance and time from takeoff to touchdown.

    Speeds follow DO_CHANGE_SPEED; DO_JUMP loops are walked (an endless loop or NAV_LOITER_UNLIM
    makes the estimate `endless`). A mission that does not end with LAND or RTL is estimated
    with a return to the start and a landing, as the run will fly it.
    """
    model = model or FlightModel()
    walk = _Walk(_start(items, home), speed_mps, model)
    walk.time += model.takeoff_s
    jumps: dict[int, int] = {}
    pc, steps, landed = 0, 0, False
    while 0 <= pc < len(items) and not landed:
        steps += 1
        if steps > model.max_steps:
            return FlightEstimate(walk.distance, walk.time, True, "DO_JUMP loops too long to walk")
        item = items[pc]
        pc += 1
        rel = relative_alt(item, home)
        here = (item.lat, item.lon) if (item.lat, item.lon) != (0.0, 0.0) else walk.pos
        if item.command == NAV_TAKEOFF:
            walk.fly_to(walk.pos[0], walk.pos[1], rel if rel is not None else item.alt)
        elif item.command == NAV_LOITER_UNLIM:
            return FlightEstimate(
                walk.distance, walk.time, True, f"NAV_LOITER_UNLIM at index {pc - 1}"
            )
        elif item.command == NAV_RETURN_TO_LAUNCH:
            walk.fly_to(walk.start[0], walk.start[1], None)
            walk.land_here()
            landed = True
        elif item.command == NAV_LAND:
            walk.fly_to(here[0], here[1], None)
            walk.land_here()
            landed = True
        elif item.command in (NAV_DELAY, CONDITION_DELAY):
            walk.time += max(
                0.0, item.params[0] or 0.0
            )  # NAV_DELAY -1: a clock time; not known here
        elif item.spec is not None and item.spec.nav and item.spec.positional:
            walk.fly_to(here[0], here[1], rel)
            _loiter(walk, item)
        elif item.command == DO_CHANGE_SPEED and item.params[1] is not None and item.params[1] > 0:
            walk.speed = float(item.params[1])
        elif item.command == DO_JUMP:
            target, repeat = item.params[0], item.params[1]
            if target is None or repeat is None:
                continue
            if repeat < 0:
                return FlightEstimate(
                    walk.distance, walk.time, True, f"endless DO_JUMP at index {pc - 1}"
                )
            left = jumps.setdefault(pc - 1, int(repeat))
            if left > 0:
                jumps[pc - 1] = left - 1
                pc = int(target) - 1  # seq -> index
    if not landed:
        walk.fly_to(walk.start[0], walk.start[1], None)
        walk.land_here()
        return FlightEstimate(
            walk.distance, walk.time, False, "no LAND/RTL at the end: return to start assumed"
        )
    return FlightEstimate(walk.distance, walk.time)


def _loiter(walk: _Walk, item: MissionItem) -> None:
    p1, p3 = item.params[0] or 0.0, item.params[2]
    radius = abs(p3) if p3 else walk.model.loiter_radius_m
    if item.command == NAV_LOITER_TIME:
        walk.time += max(0.0, p1)
    elif item.command == NAV_LOITER_TURNS:
        circle = 2 * math.pi * radius * max(0.0, p1)
        walk.distance += circle
        walk.time += circle / walk.speed
