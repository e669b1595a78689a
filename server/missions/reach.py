"""A mission flown from a base: where the flight starts, the UAV's figures and its reach. Pure.

A run takes off from its base, not from the mission's planned home: the path, the estimate and
the airspace check start and end there (the legs base -> first item and last item -> base).
A base's position is its `latitude`/`longitude` attributes (surveyed); a base without one is
taken to stand at the mission's home, as before it was known.

The reach is how far from the base the UAV can fly and still come back within its usable
endurance (the endurance less the reserve, less take-off and landing): half that time at the
mission's speed, and half the usable range when the UAV has a `max_range_m`. An item beyond it
cannot be flown however short the rest of the mission is, so it is named with its distance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from server.missions.flight import estimate_flight
from server.missions.geometry import haversine_m
from server.missions.items import NAV_TAKEOFF, MissionItem
from server.missions.validate import FlightEstimate, FlightModel, Home, Problem, check_endurance

DEFAULT_ENDURANCE_S = 1200.0
DEFAULT_CRUISE_MPS = 8.0
RESERVE = 0.2


def _positive(
    attributes: dict[str, Any], key: str, default: float, problems: list[Problem]
) -> float:
    value = attributes.get(key, default)
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        problems.append(Problem(f"uav.attributes.{key}", "must be a positive number", value))
        return default
    return float(value)


@dataclass(frozen=True)
class UavFigures:
    """What a UAV can fly: endurance, cruise speed, range (None: not limited), the reserve kept."""

    endurance_s: float = DEFAULT_ENDURANCE_S
    cruise_mps: float = DEFAULT_CRUISE_MPS
    max_range_m: float | None = None
    reserve: float = RESERVE

    @property
    def usable_endurance_s(self) -> float:
        """The endurance less the reserve."""
        return self.endurance_s * (1.0 - self.reserve)

    def reach_m(self, speed_mps: float, model: FlightModel | None = None) -> float:
        """How far from the base an item may be: out and back at `speed_mps` within the usable
        endurance after take-off and landing (and within half the usable range)."""
        model = model or FlightModel()
        flying = max(0.0, self.usable_endurance_s - model.takeoff_s - model.landing_s)
        reach = flying * speed_mps / 2.0
        if self.max_range_m is not None:
            reach = min(reach, self.max_range_m * (1.0 - self.reserve) / 2.0)
        return reach


def uav_figures(
    attributes: dict[str, Any] | None, problems: list[Problem] | None = None
) -> UavFigures:
    """The UAV's figures from its attributes (`endurance_s`, `cruise_speed_mps`, `max_range_m`);
    a value that is not a positive number is replaced by the default and named in `problems`."""
    attrs, found = attributes or {}, problems if problems is not None else []
    endurance = _positive(attrs, "endurance_s", DEFAULT_ENDURANCE_S, found)
    cruise = _positive(attrs, "cruise_speed_mps", DEFAULT_CRUISE_MPS, found)
    max_range = (
        _positive(attrs, "max_range_m", math.inf, found) if "max_range_m" in attrs else math.inf
    )
    return UavFigures(
        endurance_s=endurance,
        cruise_mps=cruise,
        max_range_m=max_range if math.isfinite(max_range) else None,
    )


def base_position(attributes: dict[str, Any] | None) -> tuple[float, float] | None:
    """The base's surveyed (lat, lon) from its attributes; None when not given or not valid."""
    attrs = attributes or {}
    lat, lon = attrs.get("latitude"), attrs.get("longitude")
    for v in (lat, lon):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            return None
    assert isinstance(lat, int | float) and isinstance(lon, int | float)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0) or (lat, lon) == (0, 0):
        return None
    return float(lat), float(lon)


def launch_home(base_attributes: dict[str, Any] | None, mission_home: Home | None) -> Home | None:
    """Where the flight starts and ends: the base's position when known (the altitude reference
    stays the mission's home, what its AMSL items were planned against), else the mission's home."""
    at = base_position(base_attributes)
    if at is None:
        return mission_home
    return Home(at[0], at[1], mission_home.alt if mission_home else 0.0)


def _flown_to(item: MissionItem) -> bool:
    """An item whose position the UAV flies to (a copter's take-off climbs where it stands)."""
    spec = item.spec
    return bool(
        spec
        and spec.nav
        and spec.positional
        and item.command != NAV_TAKEOFF
        and (item.lat, item.lon) != (0.0, 0.0)
    )


def distance_text(metres: float) -> str:
    """`1,712.4 km` from a kilometre up, else `850.0 m`."""
    return f"{metres / 1000:,.1f} km" if metres >= 1000 else f"{metres:,.1f} m"


def farthest_m(items: Sequence[MissionItem], base: Home) -> float | None:
    """The greatest distance of an item flown to from the base (None: no such item)."""
    found = [haversine_m(base.lat, base.lon, i.lat, i.lon) for i in items if _flown_to(i)]
    return max(found) if found else None


def reach_problems(
    items: Sequence[MissionItem], base: Home, base_name: str, reach_m: float
) -> list[Problem]:
    """The first item flown to that lies beyond the UAV's reach from the base, with its distance
    (value, metres) and the reach (limit, metres); none when every item is within reach."""
    flown = [(k, i) for k, i in enumerate(items) if _flown_to(i)]
    for n, (k, item) in enumerate(flown):
        d = haversine_m(base.lat, base.lon, item.lat, item.lon)
        if d > reach_m:
            which = f"the mission's first item (items[{k}])" if n == 0 else f"items[{k}]"
            return [
                Problem(
                    f"items[{k}]",
                    f"{which} is {distance_text(d)} from base {base_name}; "
                    f"the UAV's reach from it is {distance_text(reach_m)}",
                    round(d, 1),
                    round(reach_m, 1),
                    index=k,
                    command=item.command,
                    code="out_of_reach",
                )
            ]
    return []


@dataclass(frozen=True)
class FromBase:
    """A mission judged as flown from a base by one UAV: the estimate (base to base) and the
    problems a run would be refused for (reach, endurance, range)."""

    launch: Home | None
    estimate: FlightEstimate
    reach_m: float
    farthest_m: float | None
    problems: list[Problem]


def check_from_base(
    items: Sequence[MissionItem],
    speed_mps: float,
    launch: Home | None,
    base_name: str | None,
    figures: UavFigures,
) -> FromBase:
    """The flight from `launch` (the base; None: unknown) through `items` and back at `speed_mps`
    against the UAV's `figures`: its reach first, then the endurance and the range."""
    flight = estimate_flight(items, speed_mps, launch)
    reach = figures.reach_m(speed_mps)
    far = farthest_m(items, launch) if launch is not None else None
    problems: list[Problem] = []
    if launch is not None and base_name is not None:
        problems += reach_problems(items, launch, base_name, reach)
    problems += check_endurance(flight, figures.endurance_s, figures.reserve)
    if figures.max_range_m is not None:
        usable = figures.max_range_m * (1.0 - figures.reserve)
        if flight.distance_m > usable:
            problems.append(
                Problem(
                    "mission",
                    f"path length (m) exceeds the UAV's range less a {figures.reserve:.0%} reserve",
                    round(flight.distance_m, 1),
                    round(usable, 1),
                    code="range",
                )
            )
    return FromBase(launch, flight, reach, far, problems)
