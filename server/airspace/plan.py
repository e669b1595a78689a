"""A QGroundControl plan's own geoFence as zones, and a flight checked against zones and fence."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

from server.airspace.check import AirspaceProblem, ZoneShape, check_path
from server.missions.items import MissionItem
from server.missions.validate import Home


def check_flight(
    items: Sequence[MissionItem],
    home: Home | None,
    zones: Sequence[ZoneShape],
    extras: dict[str, Any] | None = None,
) -> list[AirspaceProblem]:
    """The path's problems against the zones given and the plan's own geoFence."""
    return check_path(items, home, [*zones, *plan_fence_zones(extras)])


def plan_fence_zones(extras: dict[str, Any] | None) -> list[ZoneShape]:
    """The inclusion/exclusion polygons and circles of a QGroundControl plan's geoFence."""
    fence = (extras or {}).get("geoFence")
    if not isinstance(fence, dict):
        return []
    out: list[ZoneShape] = []
    for k, poly in enumerate(fence.get("polygons") or []):
        try:
            ring = tuple((float(p[1]), float(p[0])) for p in poly["polygon"])
            kind: Literal["inclusion", "exclusion"] = (
                "inclusion" if poly.get("inclusion", True) else "exclusion"
            )
        except (KeyError, TypeError, ValueError, IndexError):
            continue
        if len(ring) >= 3:
            out.append(ZoneShape(f"plan:polygon:{k}", f"polygon {k}", kind, ring, source="plan"))
    for k, circ in enumerate(fence.get("circles") or []):
        try:
            c = circ["circle"]
            center = (float(c["center"][0]), float(c["center"][1]))
            radius = float(c["radius"])
            kind = "inclusion" if circ.get("inclusion", True) else "exclusion"
        except (KeyError, TypeError, ValueError, IndexError):
            continue
        if radius > 0:
            out.append(
                ZoneShape(
                    f"plan:circle:{k}",
                    f"circle {k}",
                    kind,
                    center=center,
                    radius_m=radius,
                    source="plan",
                )
            )
    return out
