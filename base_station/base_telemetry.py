"""The per-snapshot telemetry value of the landing base (what the server shows operators).

Axis states use one vocabulary: closed / opening / open / closing / moving / stopped / fault;
for the lift, `open` means fully up and `closed` fully down. Fields are None while unknown
(never read the PLC yet).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from base_station.snapshot import Snapshot


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True)


class AxisTelemetry(_Frozen):
    """Panels or lift."""

    state: str | None
    position_pct: float | None
    moving: bool | None


class WeatherTelemetry(_Frozen):
    """The base's weather sensors."""

    wind_mps: float
    gust_mps: float
    direction_deg: int
    rain_mm_h: float
    rain_detected: bool
    temperature_c: float
    humidity_pct: float
    sensor_ok: bool


class ChargerTelemetry(_Frozen):
    """The UAV charger."""

    enabled: bool
    state: str | None
    current_ma: int
    voltage_v: float
    current_limit_ma: int
    uav_battery_pct: float | None
    contacts_seated: bool


class PowerTelemetry(_Frozen):
    """The base's own power."""

    source: str | None
    base_battery_pct: float
    base_battery_voltage_v: float
    solar_w: int
    grid_present: bool


class StationTelemetry(_Frozen):
    """One telemetry sample of the landing base."""

    ts: float
    plc_link: str  # "up" | "down"
    plc_link_error: str
    panels: AxisTelemetry
    lift: AxisTelemetry
    uav_present: bool | None
    landing_confirmed: bool | None
    scale_mass_g: float | None
    weather: WeatherTelemetry | None
    charger: ChargerTelemetry | None
    power: PowerTelemetry | None
    estop: bool | None
    fault_bits: int | None
    faults: list[str]
    plc_heartbeat: int | None


def build_telemetry(snap: Snapshot) -> StationTelemetry:
    """Telemetry from one snapshot (last known PLC values when the link is down)."""
    s = snap.plc
    link = "up" if snap.link_up else "down"
    if s is None:
        empty = AxisTelemetry(state=None, position_pct=None, moving=None)
        return StationTelemetry(
            ts=snap.ts,
            plc_link=link,
            plc_link_error=snap.link_error,
            panels=empty,
            lift=empty,
            uav_present=None,
            landing_confirmed=None,
            scale_mass_g=None,
            weather=None,
            charger=None,
            power=None,
            estop=None,
            fault_bits=None,
            faults=[],
            plc_heartbeat=None,
        )
    landing = snap.landing
    return StationTelemetry(
        ts=snap.ts,
        plc_link=link,
        plc_link_error=snap.link_error,
        panels=AxisTelemetry(
            state=snap.panels.value if snap.panels else None,
            position_pct=s.panel_position_pct,
            moving=s.panels_moving,
        ),
        lift=AxisTelemetry(
            state=snap.lift.value if snap.lift else None,
            position_pct=s.lift_position_pct,
            moving=s.lift_moving,
        ),
        uav_present=landing.present if landing else None,
        landing_confirmed=landing.confirmed if landing else None,
        scale_mass_g=landing.mass_g if landing else float(s.scale_mass_g),
        weather=WeatherTelemetry(
            wind_mps=s.wind_speed_mps,
            gust_mps=s.wind_gust_mps,
            direction_deg=s.wind_direction_deg,
            rain_mm_h=s.rain_rate_mm_h,
            rain_detected=s.rain_detected,
            temperature_c=s.temperature_c,
            humidity_pct=s.humidity_pct,
            sensor_ok="WEATHER_SENSOR" not in s.fault_names,
        ),
        charger=ChargerTelemetry(
            enabled=s.charger_enable,
            state=s.charger_state.name.lower() if s.charger_state is not None else None,
            current_ma=s.charge_current_ma,
            voltage_v=s.charge_voltage_v,
            current_limit_ma=s.charge_current_limit_ma,
            uav_battery_pct=s.uav_battery_soc_pct,
            contacts_seated=s.charger_contact,
        ),
        power=PowerTelemetry(
            source=s.power_source.name.lower() if s.power_source is not None else None,
            base_battery_pct=s.base_battery_soc_pct,
            base_battery_voltage_v=s.base_battery_voltage_v,
            solar_w=s.solar_power_w,
            grid_present=s.grid_present,
        ),
        estop=s.estop_active,
        fault_bits=int(s.fault_bits),
        faults=list(s.fault_names),
        plc_heartbeat=s.heartbeat,
    )
