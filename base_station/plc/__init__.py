"""The landing-base PLC over Modbus TCP: register map, pure codec, async client, watchdog.

This package is the only code of the daemon that imports pymodbus.
"""

from base_station.plc.client import PlcClient, PlcLinkError
from base_station.plc.codec import PlcState, RawImage, decode, encode, fault_names
from base_station.plc.registers import (
    MOTION_BLOCKING_FAULTS,
    UNIT_ID,
    ChargerState,
    Coil,
    DiscreteInput,
    FaultBit,
    HoldingRegister,
    InputRegister,
    PowerSource,
)
from base_station.plc.watchdog import WatchdogWriter

__all__ = [
    "MOTION_BLOCKING_FAULTS",
    "UNIT_ID",
    "ChargerState",
    "Coil",
    "DiscreteInput",
    "FaultBit",
    "HoldingRegister",
    "InputRegister",
    "PlcClient",
    "PlcLinkError",
    "PlcState",
    "PowerSource",
    "RawImage",
    "WatchdogWriter",
    "decode",
    "encode",
    "fault_names",
]
