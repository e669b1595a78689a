"""Pure encode/decode between the PLC's raw register image and a frozen `PlcState`."""

from __future__ import annotations

from dataclasses import dataclass

from base_station.plc.registers import (
    COIL_COUNT,
    DISCRETE_COUNT,
    HOLDING_COUNT,
    INPUT_COUNT,
    UNKNOWN_SOC,
    ChargerState,
    Coil,
    DiscreteInput,
    FaultBit,
    HoldingRegister,
    InputRegister,
    PowerSource,
)


class DecodeError(ValueError):
    """The raw image is too short or malformed."""


@dataclass(frozen=True)
class RawImage:
    """The four Modbus tables as read from the PLC."""

    coils: tuple[bool, ...]
    discrete: tuple[bool, ...]
    inputs: tuple[int, ...]
    holding: tuple[int, ...]


@dataclass(frozen=True)
class PlcState:
    """Everything the PLC reports, decoded to engineering units."""

    # coils
    pending_commands: tuple[Coil, ...]
    charger_enable: bool
    # discrete inputs
    panels_open_limit: bool
    panels_closed_limit: bool
    lift_up_limit: bool
    lift_down_limit: bool
    panels_moving: bool
    lift_moving: bool
    estop_active: bool
    rain_detected: bool
    grid_present: bool
    charger_contact: bool
    interlock_refused: bool
    # input registers
    scale_mass_g: int
    wind_speed_mps: float
    wind_gust_mps: float
    wind_direction_deg: int
    rain_rate_mm_h: float
    temperature_c: float
    humidity_pct: float
    charger_state: ChargerState | None
    charge_current_ma: int
    charge_voltage_v: float
    uav_battery_soc_pct: float | None
    base_battery_soc_pct: float
    base_battery_voltage_v: float
    solar_power_w: int
    power_source: PowerSource | None
    panel_position_pct: float
    lift_position_pct: float
    fault_bits: FaultBit
    heartbeat: int
    # holding registers
    watchdog: int
    charge_current_limit_ma: int

    @property
    def fault_names(self) -> tuple[str, ...]:
        """Names of the fault bits set, e.g. ("PANEL_STALL", "ESTOP")."""
        return fault_names(self.fault_bits)


def fault_names(bits: FaultBit | int) -> tuple[str, ...]:
    """Names of the fault bits set in `bits`."""
    return tuple(f.name or str(int(f)) for f in FaultBit if int(bits) & int(f))


def _int16(value: int) -> int:
    return value - 0x10000 if value & 0x8000 else value


def _enum_or_none(enum: type[ChargerState] | type[PowerSource], value: int):  # type: ignore[no-untyped-def]
    try:
        return enum(value)
    except ValueError:
        return None


def decode(raw: RawImage) -> PlcState:
    """Raw register image -> PlcState (raises DecodeError on a short image)."""
    c, d, i, h = raw.coils, raw.discrete, raw.inputs, raw.holding
    if (
        len(c) < COIL_COUNT
        or len(d) < DISCRETE_COUNT
        or len(i) < INPUT_COUNT
        or len(h) < HOLDING_COUNT
    ):
        raise DecodeError(
            f"short image: coils {len(c)}, discrete {len(d)}, inputs {len(i)}, holding {len(h)}"
        )
    ir = InputRegister
    di = DiscreteInput
    soc = i[ir.UAV_BATTERY_SOC]
    commands = tuple(k for k in Coil if k is not Coil.CHARGER_ENABLE and c[k])
    return PlcState(
        pending_commands=commands,
        charger_enable=bool(c[Coil.CHARGER_ENABLE]),
        panels_open_limit=bool(d[di.PANELS_OPEN_LIMIT]),
        panels_closed_limit=bool(d[di.PANELS_CLOSED_LIMIT]),
        lift_up_limit=bool(d[di.LIFT_UP_LIMIT]),
        lift_down_limit=bool(d[di.LIFT_DOWN_LIMIT]),
        panels_moving=bool(d[di.PANELS_MOVING]),
        lift_moving=bool(d[di.LIFT_MOVING]),
        estop_active=bool(d[di.ESTOP_ACTIVE]),
        rain_detected=bool(d[di.RAIN_DETECTED]),
        grid_present=bool(d[di.GRID_PRESENT]),
        charger_contact=bool(d[di.CHARGER_CONTACT]),
        interlock_refused=bool(d[di.INTERLOCK_REFUSED]),
        scale_mass_g=(i[ir.SCALE_MASS_HI] << 16) | i[ir.SCALE_MASS_LO],
        wind_speed_mps=i[ir.WIND_SPEED] / 100.0,
        wind_gust_mps=i[ir.WIND_GUST] / 100.0,
        wind_direction_deg=i[ir.WIND_DIRECTION],
        rain_rate_mm_h=i[ir.RAIN_RATE] / 10.0,
        temperature_c=_int16(i[ir.TEMPERATURE]) / 10.0,
        humidity_pct=i[ir.HUMIDITY] / 10.0,
        charger_state=_enum_or_none(ChargerState, i[ir.CHARGER_STATE]),
        charge_current_ma=i[ir.CHARGE_CURRENT],
        charge_voltage_v=i[ir.CHARGE_VOLTAGE] / 100.0,
        uav_battery_soc_pct=None if soc == UNKNOWN_SOC else soc / 10.0,
        base_battery_soc_pct=i[ir.BASE_BATTERY_SOC] / 10.0,
        base_battery_voltage_v=i[ir.BASE_BATTERY_VOLTAGE] / 100.0,
        solar_power_w=i[ir.SOLAR_POWER],
        power_source=_enum_or_none(PowerSource, i[ir.POWER_SOURCE]),
        panel_position_pct=i[ir.PANEL_POSITION] / 10.0,
        lift_position_pct=i[ir.LIFT_POSITION] / 10.0,
        fault_bits=FaultBit(i[ir.FAULT_BITS] & 0x3F),
        heartbeat=i[ir.PLC_HEARTBEAT],
        watchdog=h[HoldingRegister.WATCHDOG],
        charge_current_limit_ma=h[HoldingRegister.CHARGE_CURRENT_LIMIT],
    )


def _u16(value: float) -> int:
    return max(0, min(0xFFFF, round(value)))


def encode(s: PlcState) -> RawImage:
    """PlcState -> raw register image (the inverse of `decode`, for tests and tools)."""
    coils = [False] * COIL_COUNT
    for k in s.pending_commands:
        coils[k] = True
    coils[Coil.CHARGER_ENABLE] = s.charger_enable
    discrete = [
        s.panels_open_limit,
        s.panels_closed_limit,
        s.lift_up_limit,
        s.lift_down_limit,
        s.panels_moving,
        s.lift_moving,
        s.estop_active,
        s.rain_detected,
        s.grid_present,
        s.charger_contact,
        s.interlock_refused,
    ]
    mass = max(0, min(0xFFFFFFFF, s.scale_mass_g))
    soc = UNKNOWN_SOC if s.uav_battery_soc_pct is None else _u16(s.uav_battery_soc_pct * 10)
    inputs = [
        mass >> 16,
        mass & 0xFFFF,
        _u16(s.wind_speed_mps * 100),
        _u16(s.wind_gust_mps * 100),
        _u16(s.wind_direction_deg),
        _u16(s.rain_rate_mm_h * 10),
        round(s.temperature_c * 10) & 0xFFFF,
        _u16(s.humidity_pct * 10),
        3 if s.charger_state is None else int(s.charger_state),
        _u16(s.charge_current_ma),
        _u16(s.charge_voltage_v * 100),
        soc,
        _u16(s.base_battery_soc_pct * 10),
        _u16(s.base_battery_voltage_v * 100),
        _u16(s.solar_power_w),
        2 if s.power_source is None else int(s.power_source),
        _u16(s.panel_position_pct * 10),
        _u16(s.lift_position_pct * 10),
        int(s.fault_bits),
        s.heartbeat & 0xFFFF,
    ]
    holding = [s.watchdog & 0xFFFF, s.charge_current_limit_ma & 0xFFFF]
    return RawImage(tuple(coils), tuple(discrete), tuple(inputs), tuple(holding))
