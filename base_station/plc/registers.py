"""The landing-base PLC register map (spec: shared/specs/plc-modbus.md rev. A) — the only copy.

Modbus TCP, unit id 1, zero-based addresses, 32-bit values high word first.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag

UNIT_ID = 1
UNKNOWN_SOC = 65535


class Coil(IntEnum):
    """Coils (FC01 read, FC05/FC15 write). Command coils are cleared by the PLC."""

    PANELS_OPEN = 0
    PANELS_CLOSE = 1
    LIFT_UP = 2
    LIFT_DOWN = 3
    MOTION_STOP = 4
    CHARGER_ENABLE = 5
    FAULT_RESET = 6


class DiscreteInput(IntEnum):
    """Discrete inputs (FC02)."""

    PANELS_OPEN_LIMIT = 0
    PANELS_CLOSED_LIMIT = 1
    LIFT_UP_LIMIT = 2
    LIFT_DOWN_LIMIT = 3
    PANELS_MOVING = 4
    LIFT_MOVING = 5
    ESTOP_ACTIVE = 6
    RAIN_DETECTED = 7
    GRID_PRESENT = 8
    CHARGER_CONTACT = 9
    INTERLOCK_REFUSED = 10


class InputRegister(IntEnum):
    """Input registers (FC04)."""

    SCALE_MASS_HI = 0
    SCALE_MASS_LO = 1
    WIND_SPEED = 2
    WIND_GUST = 3
    WIND_DIRECTION = 4
    RAIN_RATE = 5
    TEMPERATURE = 6
    HUMIDITY = 7
    CHARGER_STATE = 8
    CHARGE_CURRENT = 9
    CHARGE_VOLTAGE = 10
    UAV_BATTERY_SOC = 11
    BASE_BATTERY_SOC = 12
    BASE_BATTERY_VOLTAGE = 13
    SOLAR_POWER = 14
    POWER_SOURCE = 15
    PANEL_POSITION = 16
    LIFT_POSITION = 17
    FAULT_BITS = 18
    PLC_HEARTBEAT = 19


class HoldingRegister(IntEnum):
    """Holding registers (FC03 read, FC06/FC16 write)."""

    WATCHDOG = 0
    CHARGE_CURRENT_LIMIT = 1


class FaultBit(IntFlag):
    """FAULT_BITS."""

    PANEL_STALL = 1
    LIFT_STALL = 2
    CHARGER = 4
    WEATHER_SENSOR = 8
    WATCHDOG = 16
    ESTOP = 32


# Faults the PLC latches and that forbid motion until FAULT_RESET.
MOTION_BLOCKING_FAULTS = (
    FaultBit.PANEL_STALL | FaultBit.LIFT_STALL | FaultBit.WATCHDOG | FaultBit.ESTOP
)


class ChargerState(IntEnum):
    """CHARGER_STATE values."""

    IDLE = 0
    CHARGING = 1
    COMPLETE = 2
    FAULT = 3


class PowerSource(IntEnum):
    """POWER_SOURCE values."""

    GRID = 0
    SOLAR = 1
    BATTERY = 2


COIL_COUNT = len(Coil)
DISCRETE_COUNT = len(DiscreteInput)
INPUT_COUNT = len(InputRegister)
HOLDING_COUNT = len(HoldingRegister)
