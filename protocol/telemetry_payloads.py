"""Telemetry payloads, discriminated by asset kind: a `uav` or a `landing_base`.

Optional fields are None when the asset has no such sensor or no reading yet. Numbers are finite
(NaN and infinities are refused, see `protocol.base.Frozen`) and integers bounded.
Units are in the field names (m, m_s, deg, pct, v, a, w, g, mm_h, c).
"""

from __future__ import annotations

from typing import Annotated, Literal
from uuid import UUID

from pydantic import Field

from protocol.base import MAX_SAFE_INT, Frozen

Pct = Annotated[float, Field(ge=0, le=100)]
Deg360 = Annotated[float, Field(ge=0, le=360)]

GnssFix = Literal["none", "2d", "3d", "dgps", "rtk_float", "rtk_fixed"]
LandedState = Literal["unknown", "on_ground", "in_air", "takeoff", "landing"]
MotionState = Literal["closed", "opening", "open", "closing", "moving", "fault", "stopped"]
ChargerState = Literal["idle", "charging", "complete", "fault"]
PowerSource = Literal["grid", "solar", "battery"]
LinkState = Literal["up", "down"]

# Bits of the PLC's FAULT_BITS input register (specs/plc-modbus.md).
FAULT_NAMES: dict[int, str] = {
    1: "panel_motor_stall",
    2: "lift_motor_stall",
    4: "charger_fault",
    8: "weather_sensor_fault",
    16: "watchdog_expired",
    32: "estop",
}


class Position(Frozen):
    """WGS84 position with altitude above mean sea level and above home."""

    lat: Annotated[float, Field(ge=-90, le=90)]
    lon: Annotated[float, Field(ge=-180, le=180)]
    alt_msl_m: float
    alt_rel_m: float


class Velocity(Frozen):
    """Ground velocity in the local NED frame."""

    north_m_s: float
    east_m_s: float
    down_m_s: float


class Attitude(Frozen):
    """Vehicle attitude in degrees."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


class Battery(Frozen):
    """Flight battery state."""

    percent: Pct | None = None
    voltage_v: float | None = None
    current_a: float | None = None


class Gnss(Frozen):
    """GNSS receiver state, including RTK float/fixed solutions."""

    fix: GnssFix
    satellites: Annotated[int, Field(ge=0, le=255)] | None = None
    hdop: Annotated[float, Field(ge=0)] | None = None


class MissionProgress(Frozen):
    """Current mission item out of the total uploaded."""

    current: Annotated[int, Field(ge=0, le=65535)]  # MAVLink mission sequence numbers are uint16
    total: Annotated[int, Field(ge=0, le=65535)]


class UavTelemetry(Frozen):
    """One telemetry sample of a UAV."""

    kind: Literal["uav"] = "uav"
    asset_id: UUID | None = None
    position: Position | None = None
    velocity: Velocity | None = None
    heading_deg: Deg360 | None = None
    attitude: Attitude | None = None
    battery: Battery | None = None
    gnss: Gnss | None = None
    flight_mode: str | None = None
    armed: bool = False
    landed_state: LandedState = "unknown"
    mission: MissionProgress | None = None


class Actuator(Frozen):
    """Panels or lift: motion state and position (0 % closed/down, 100 % open/up)."""

    state: MotionState
    position_pct: Pct | None = None


class Weather(Frozen):
    """The base's weather station."""

    wind_m_s: Annotated[float, Field(ge=0)] | None = None
    gust_m_s: Annotated[float, Field(ge=0)] | None = None
    direction_deg: Deg360 | None = None
    rain_mm_h: Annotated[float, Field(ge=0)] | None = None
    rain_detected: bool | None = None
    temperature_c: float | None = None
    humidity_pct: Pct | None = None


class Charger(Frozen):
    """The pad charger and the UAV battery it sees."""

    state: ChargerState
    enabled: bool | None = None
    contact: bool | None = None
    current_a: float | None = None
    voltage_v: float | None = None
    uav_battery_pct: Pct | None = None


class Power(Frozen):
    """The base's own power supply."""

    source: PowerSource | None = None
    battery_pct: Pct | None = None
    battery_v: float | None = None
    solar_w: Annotated[float, Field(ge=0)] | None = None
    grid_present: bool | None = None


class Rtk(Frozen):
    """The base's RTK reference receiver and its correction stream."""

    state: str
    corrections_rate: Annotated[float, Field(ge=0)] = 0.0
    # seconds since the last good frame (None before the first): stale corrections degrade RTK
    correction_age_s: Annotated[float, Field(ge=0, le=1e9)] | None = None
    frames_total: Annotated[int, Field(ge=0, le=MAX_SAFE_INT)] = 0
    bad_frames: Annotated[int, Field(ge=0, le=MAX_SAFE_INT)] = 0


class Faults(Frozen):
    """Latched PLC fault bits and their decoded names."""

    bits: Annotated[int, Field(ge=0, le=0xFFFF)] = 0
    names: tuple[str, ...] = ()

    @classmethod
    def from_bits(cls, bits: int) -> Faults:
        """Decode a FAULT_BITS register value into named faults."""
        names = [name for bit, name in FAULT_NAMES.items() if bits & bit]
        names += [f"bit_{i}" for i in range(16) if bits & (1 << i) and (1 << i) not in FAULT_NAMES]
        return cls(bits=bits, names=tuple(names))


class LandingBaseTelemetry(Frozen):
    """One telemetry sample of a landing base (after DJI's dock `osd` and the PLC map)."""

    kind: Literal["landing_base"] = "landing_base"
    asset_id: UUID | None = None
    plc_link: LinkState = "down"
    panels: Actuator | None = None
    lift: Actuator | None = None
    uav_present: bool | None = None
    landing_confirmed: bool | None = None  # the UAV's mass in its window and stable
    scale_mass_g: Annotated[float, Field(ge=0)] | None = None
    weather: Weather | None = None
    charger: Charger | None = None
    power: Power | None = None
    rtk: Rtk | None = None
    estop: bool | None = None
    faults: Faults = Faults()


TelemetryPayload = Annotated[UavTelemetry | LandingBaseTelemetry, Field(discriminator="kind")]
