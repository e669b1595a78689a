"""The base's telemetry message, built straight from one coordinator snapshot.

What the server shows operators: `protocol`'s `LandingBaseTelemetry`, with the PLC's last known
values when the link is down and None fields before the first read. Axis states use one
vocabulary (closed / opening / open / closing / moving / stopped / fault); for the lift `open`
means fully up and `closed` fully down. Readings are clamped into the ranges the wire model
allows (a scale reading below zero, a humidity above 100 %) rather than refused.
"""

from __future__ import annotations

from typing import cast

from base_station.devices.axis import MotionState
from base_station.plc.codec import PlcState
from base_station.plc.registers import ChargerState, PowerSource
from base_station.snapshot import Snapshot
from protocol.telemetry_payloads import (
    Actuator,
    Charger,
    Faults,
    LandingBaseTelemetry,
    LinkState,
    Power,
    Rtk,
    Weather,
)
from protocol.telemetry_payloads import ChargerState as WireChargerState
from protocol.telemetry_payloads import MotionState as WireMotionState
from protocol.telemetry_payloads import PowerSource as WirePowerSource

CHARGER_STATES: dict[ChargerState, WireChargerState] = {
    ChargerState.IDLE: "idle",
    ChargerState.CHARGING: "charging",
    ChargerState.COMPLETE: "complete",
    ChargerState.FAULT: "fault",
}
POWER_SOURCES: dict[PowerSource, WirePowerSource] = {
    PowerSource.GRID: "grid",
    PowerSource.SOLAR: "solar",
    PowerSource.BATTERY: "battery",
}


def _clamp(value: float, low: float = 0.0, high: float = 100.0) -> float:
    return min(high, max(low, value))


def _actuator(state: MotionState | None, position_pct: float) -> Actuator | None:
    if state is None:
        return None
    # the daemon's MotionState values are the wire's, one for one
    return Actuator(state=cast(WireMotionState, state.value), position_pct=_clamp(position_pct))


def _weather(s: PlcState) -> Weather:
    return Weather(
        wind_m_s=max(0.0, s.wind_speed_mps),
        gust_m_s=max(0.0, s.wind_gust_mps),
        direction_deg=s.wind_direction_deg % 360,
        rain_mm_h=max(0.0, s.rain_rate_mm_h),
        rain_detected=s.rain_detected,
        temperature_c=s.temperature_c,
        humidity_pct=_clamp(s.humidity_pct),
    )


def _charger(s: PlcState) -> Charger:
    soc = s.uav_battery_soc_pct
    return Charger(
        state="idle" if s.charger_state is None else CHARGER_STATES[s.charger_state],
        enabled=s.charger_enable,
        contact=s.charger_contact,
        current_a=s.charge_current_ma / 1000,
        voltage_v=s.charge_voltage_v,
        uav_battery_pct=None if soc is None else _clamp(soc),
    )


def _power(s: PlcState) -> Power:
    return Power(
        source=None if s.power_source is None else POWER_SOURCES[s.power_source],
        battery_pct=_clamp(s.base_battery_soc_pct),
        battery_v=s.base_battery_voltage_v,
        solar_w=max(0, s.solar_power_w),
        grid_present=s.grid_present,
    )


def build_telemetry(snap: Snapshot, rtk: Rtk | None = None) -> LandingBaseTelemetry:
    """The telemetry message of one snapshot, with the RTK receiver's state when there is one."""
    s = snap.plc
    link: LinkState = "up" if snap.link_up else "down"
    if s is None:  # never read the PLC yet: only the link is known
        return LandingBaseTelemetry(plc_link=link, rtk=rtk)
    landing = snap.landing
    mass = landing.mass_g if landing else float(s.scale_mass_g)
    return LandingBaseTelemetry(
        plc_link=link,
        panels=_actuator(snap.panels, s.panel_position_pct),
        lift=_actuator(snap.lift, s.lift_position_pct),
        uav_present=landing.present if landing else None,
        landing_confirmed=landing.confirmed if landing else None,
        scale_mass_g=max(0.0, mass),
        weather=_weather(s),
        charger=_charger(s),
        power=_power(s),
        rtk=rtk,
        estop=s.estop_active,
        faults=Faults.from_bits(int(s.fault_bits)),
    )
