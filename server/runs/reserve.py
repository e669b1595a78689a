"""The energy to get home: from where the UAV is, against the wind the base measures. Pure.

The return is flown straight to the base at cruise speed; the wind the base's station reports
(speed, and the direction it blows FROM) adds its component along that track to the ground
speed (a headwind slows the return, never below `min_ground_mps`), then the descent and the
landing. The battery that takes is the return's duration times the UAV's consumption
(`consumption_pct_per_s`: the UAV's attribute when set, e.g. learnt from its past runs'
battery used per flight second, else the default). The run sends the UAV home once what is left
after that return would fall below the reserve, so it lands with the reserve still in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from server.missions.geometry import LocalProjection


@dataclass(frozen=True)
class ReturnModel:
    """How the return is flown and what it costs."""

    cruise_mps: float = 8.0
    descent_mps: float = 1.5  # WPNAV_SPEED_DN
    landing_s: float = 30.0  # the final slow descent and the precision landing
    consumption_pct_per_s: float = 0.1  # battery percent a flight second (17 A on 5 Ah ~ 0.094)
    reserve_pct: float = 20.0
    min_ground_mps: float = 1.0
    # home is out of reach once flying there now would land with less than this: the run lands
    # the UAV where it is instead (ArduPilot's critical battery level, BATT_CRT_PCT, lands it too)
    critical_pct: float = 5.0
    home_radius_m: float = 50.0  # over the base: its own landing, whatever the battery


def return_need_pct(
    uav: tuple[float, float, float],
    base: tuple[float, float],
    wind_mps: float | None,
    wind_from_deg: float | None,
    model: ReturnModel,
) -> float:
    """Battery percent needed to fly from `uav` (lat, lon, metres above the base) home and land."""
    proj = LocalProjection(base[0], base[1])
    x, y = proj.to_local(uav[0], uav[1])  # east, north of the base
    distance = math.hypot(x, y)
    along = 0.0
    if distance > 0 and wind_mps and wind_from_deg is not None:
        rad = math.radians(wind_from_deg)
        wind_e, wind_n = -wind_mps * math.sin(rad), -wind_mps * math.cos(rad)  # air velocity
        along = (wind_e * -x + wind_n * -y) / distance  # its component along the track home
    ground = max(model.min_ground_mps, model.cruise_mps + along)
    seconds = distance / ground + max(0.0, uav[2]) / model.descent_mps + model.landing_s
    return seconds * model.consumption_pct_per_s


@dataclass(frozen=True)
class HomeReach:
    """Flying home now, as the run judges it (percent of the battery)."""

    battery_pct: float
    need_pct: float  # the return's cost (return_need_pct)
    margin_pct: float  # left above the reserve on arrival (negative: the reserve is reached)
    out_of_reach: bool  # it would land home with less than the critical level


def home_reach(
    battery_pct: float,
    uav: tuple[float, float, float],
    base: tuple[float, float],
    wind_mps: float | None,
    wind_from_deg: float | None,
    model: ReturnModel,
) -> HomeReach:
    """What flying home now would cost and leave; out of reach below `critical_pct` on arrival,
    unless it is home already (within `home_radius_m` of the base: landing there is landing home,
    however little the battery holds)."""
    need = return_need_pct(uav, base, wind_mps, wind_from_deg, model)
    left = battery_pct - need
    away = math.hypot(*LocalProjection(base[0], base[1]).to_local(uav[0], uav[1]))
    out = left < model.critical_pct and away > model.home_radius_m
    return HomeReach(battery_pct, need, left - model.reserve_pct, out)


def finite(v: Any) -> float | None:
    """The value as a float when it is a finite number, else None."""
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def return_model(attributes: dict[str, Any], mission: Any) -> ReturnModel:
    """The return's figures: the UAV's attributes (`consumption_pct_per_s`,
    `battery_reserve_pct`, `battery_critical_pct`, `cruise_speed_mps`) or the mission's speed,
    else the defaults."""
    d = ReturnModel()
    values = {
        "consumption_pct_per_s": finite(attributes.get("consumption_pct_per_s")),
        "reserve_pct": finite(attributes.get("battery_reserve_pct")),
        "critical_pct": finite(attributes.get("battery_critical_pct")),
        "cruise_mps": finite(getattr(mission, "speed_mps", None))
        or finite(attributes.get("cruise_speed_mps")),
    }
    kept = {k: v for k, v in values.items() if v is not None and v > 0}
    return ReturnModel(**{**d.__dict__, **kept})
