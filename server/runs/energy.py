"""The run's margin to get home now, and whether home is in reach at all, from what it observes (the pure rules are in reserve.py)."""

from __future__ import annotations

from typing import Any

from server.assets.models import Asset
from server.runs.models import Run
from server.runs.reserve import HomeReach, finite, home_reach, return_model


async def return_reach(
    db: Any, run: Run, uav: dict[str, Any], base: dict[str, Any]
) -> HomeReach | None:
    """What flying home now would cost and leave (reserve.py); None unknown. Home is the run's
    base (its position; unknown: the mission's home)."""
    from server.missions.models import Mission
    from server.missions.reach import base_position

    mission = await db.get(Mission, run.mission_id)
    asset = await db.get(Asset, run.uav_id)
    station = await db.get(Asset, run.base_id)
    planned = (mission.home or {}) if mission else {}
    home = base_position(station.attributes if station else None) or (
        (float(planned["lat"]), float(planned["lon"])) if "lat" in planned else None
    )
    fields = ("position.lat", "position.lon", "position.alt_rel_m", "battery.percent")
    values = [finite(uav.get(k)) for k in fields]
    if home is None or any(v is None for v in values):
        return None
    lat, lon, alt, battery = (float(v) for v in values if v is not None)
    return home_reach(
        battery,
        (lat, lon, alt),
        home,
        finite(base.get("weather.wind_m_s")),
        finite(base.get("weather.direction_deg")),
        return_model((asset.attributes if asset else None) or {}, mission),
    )
