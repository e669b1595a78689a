"""Weather go/no-go: each measured value against its configured limit."""

from __future__ import annotations

from dataclasses import dataclass

from base_station.plc.codec import PlcState
from base_station.plc.registers import FaultBit


@dataclass(frozen=True)
class Condition:
    """One availability condition: its measured value, its limit, and whether it holds."""

    name: str
    ok: bool
    measured: float | str | bool | None
    limit: float | str | bool | None
    message: str


def weather_conditions(
    plc: PlcState,
    max_wind_mps: float,
    max_gust_mps: float,
    max_rain_mm_h: float,
    min_temperature_c: float,
    max_temperature_c: float,
) -> list[Condition]:
    """Wind, gust, rain and temperature against their limits (sensor fault fails them all)."""
    if plc.fault_bits & FaultBit.WEATHER_SENSOR:
        return [
            Condition(
                "weather_sensor",
                False,
                "fault",
                "ok",
                "weather sensor fault: wind, rain and temperature unknown",
            )
        ]
    rain = max(plc.rain_rate_mm_h, 0.1 if plc.rain_detected else 0.0)
    t = plc.temperature_c
    return [
        Condition(
            "wind",
            plc.wind_speed_mps <= max_wind_mps,
            plc.wind_speed_mps,
            max_wind_mps,
            f"wind {plc.wind_speed_mps:.1f} m/s (max {max_wind_mps:.1f})",
        ),
        Condition(
            "gust",
            plc.wind_gust_mps <= max_gust_mps,
            plc.wind_gust_mps,
            max_gust_mps,
            f"gust {plc.wind_gust_mps:.1f} m/s (max {max_gust_mps:.1f})",
        ),
        Condition(
            "rain",
            rain <= max_rain_mm_h,
            plc.rain_rate_mm_h,
            max_rain_mm_h,
            f"rain {plc.rain_rate_mm_h:.1f} mm/h (max {max_rain_mm_h:.1f})",
        ),
        Condition(
            "temperature_min",
            t >= min_temperature_c,
            t,
            min_temperature_c,
            f"temperature {t:.1f} °C (min {min_temperature_c:.1f})",
        ),
        Condition(
            "temperature_max",
            t <= max_temperature_c,
            t,
            max_temperature_c,
            f"temperature {t:.1f} °C (max {max_temperature_c:.1f})",
        ),
    ]
