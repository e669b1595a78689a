"""The simulated landing-base PLC: a pure physics model and its Modbus TCP server."""

from sim.plc.charger import Charger, ChargerState
from sim.plc.model import BaseParams, CommandRecord, LandingBase
from sim.plc.server import LinkMode, PlcServer

__all__ = [
    "BaseParams",
    "Charger",
    "ChargerState",
    "CommandRecord",
    "LandingBase",
    "LinkMode",
    "PlcServer",
]
