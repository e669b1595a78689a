"""Async Modbus TCP client for the landing-base PLC: connect/reconnect, read state, write.

Every pymodbus error, timeout or exception response is translated at this edge into
`PlcLinkError`; after one the connection is closed so the next call reconnects cleanly.
"""

from __future__ import annotations

import asyncio
import logging

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from base_station.plc.codec import PlcState, RawImage, decode
from base_station.plc.registers import (
    COIL_COUNT,
    DISCRETE_COUNT,
    HOLDING_COUNT,
    INPUT_COUNT,
    UNIT_ID,
    Coil,
    HoldingRegister,
)

log = logging.getLogger(__name__)


class PlcLinkError(Exception):
    """The PLC could not be reached, did not answer in time, or answered with an error."""


class PlcClient:
    """One Modbus TCP connection to the PLC; methods raise `PlcLinkError` on any failure."""

    def __init__(self, host: str, port: int, unit: int = UNIT_ID, timeout_s: float = 1.0) -> None:
        self.host, self.port, self.unit, self.timeout_s = host, port, unit, timeout_s
        self._client: AsyncModbusTcpClient | None = None

    @property
    def connected(self) -> bool:
        """Whether a connection is currently open."""
        return self._client is not None and self._client.connected

    async def connect(self) -> None:
        """Open the connection (one attempt), replacing any previous one."""
        self.close()
        client = AsyncModbusTcpClient(
            self.host,
            port=self.port,
            timeout=self.timeout_s,
            retries=0,
            reconnect_delay=0,
            reconnect_delay_max=0,
        )
        try:
            ok = await asyncio.wait_for(client.connect(), self.timeout_s * 2)
        except (TimeoutError, OSError, ModbusException) as err:
            client.close()
            raise PlcLinkError(f"cannot connect to PLC at {self.host}:{self.port}: {err}") from err
        if not ok:
            client.close()
            raise PlcLinkError(f"cannot connect to PLC at {self.host}:{self.port}")
        self._client = client

    def close(self) -> None:
        """Close the connection if open."""
        if self._client is not None:
            self._client.close()
            self._client = None

    async def _call(self, what: str, coro_factory):  # type: ignore[no-untyped-def]
        client = self._client
        if client is None or not client.connected:
            self.close()
            raise PlcLinkError("PLC link down")
        try:
            response = await asyncio.wait_for(coro_factory(client), self.timeout_s * 1.5)
        except (TimeoutError, OSError, ModbusException) as err:
            self.close()
            raise PlcLinkError(f"{what} failed: {err or type(err).__name__}") from err
        if response.isError():
            self.close()
            raise PlcLinkError(f"{what}: PLC answered with an exception ({response})")
        return response

    async def read_raw(self) -> RawImage:
        """Read all four tables."""
        u = self.unit
        co = await self._call(
            "read coils", lambda c: c.read_coils(0, count=COIL_COUNT, device_id=u)
        )
        di = await self._call(
            "read discrete inputs",
            lambda c: c.read_discrete_inputs(0, count=DISCRETE_COUNT, device_id=u),
        )
        ir = await self._call(
            "read input registers",
            lambda c: c.read_input_registers(0, count=INPUT_COUNT, device_id=u),
        )
        hr = await self._call(
            "read holding registers",
            lambda c: c.read_holding_registers(0, count=HOLDING_COUNT, device_id=u),
        )
        return RawImage(
            tuple(co.bits[:COIL_COUNT]),
            tuple(di.bits[:DISCRETE_COUNT]),
            tuple(ir.registers[:INPUT_COUNT]),
            tuple(hr.registers[:HOLDING_COUNT]),
        )

    async def read_state(self) -> PlcState:
        """Read and decode the PLC's whole state."""
        raw = await self.read_raw()
        try:
            return decode(raw)
        except ValueError as err:
            self.close()
            raise PlcLinkError(f"PLC sent an undecodable image: {err}") from err

    async def write_coil(self, coil: Coil, value: bool) -> None:
        """Write one coil (FC05)."""
        await self._call(
            f"write {coil.name}", lambda c: c.write_coil(int(coil), value, device_id=self.unit)
        )

    async def write_register(self, register: HoldingRegister, value: int) -> None:
        """Write one holding register (FC06)."""
        await self._call(
            f"write {register.name}",
            lambda c: c.write_register(int(register), value & 0xFFFF, device_id=self.unit),
        )
