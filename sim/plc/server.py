"""Serves a `LandingBase` over Modbus TCP (pymodbus, unit id 1), with link fault injection.

The pymodbus server listens on an internal ephemeral port on 127.0.0.1 and answers from
the live model through a `SimDevice` action (reads refresh the block from the model, writes
go to the model). A small TCP relay listens on the public port and carries the bytes, so the
link can be broken like a real cable or switch would break it:

- `normal`: bytes flow both ways;
- `cut`: every open connection is closed and new ones are closed as soon as accepted;
- `freeze`: connections are accepted and requests read, but nothing is ever answered
  (leaving freeze closes the frozen connections so masters reconnect cleanly).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from enum import StrEnum
from typing import Any

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from asynckit.tasks import cancel_and_wait
from sim.plc.model import N_COILS, N_DISCRETE, N_HOLDING, N_INPUT, LandingBase

log = logging.getLogger(__name__)

UNIT_ID = 1
_BIT_FCS = {1: "c", 5: "c", 15: "c", 2: "d"}
_REG_FCS = {3: "h", 6: "h", 16: "h", 22: "h", 23: "h", 4: "i"}


class LinkMode(StrEnum):
    """State of the simulated cable between the PLC and its master."""

    NORMAL = "normal"
    CUT = "cut"
    FREEZE = "freeze"


def pack_bits(bits: list[bool]) -> list[int]:
    """Bits (bit 0 first) packed into 16-bit words, least significant bit first."""
    words = [0] * ((len(bits) + 15) // 16)
    for i, bit in enumerate(bits):
        if bit:
            words[i // 16] |= 1 << (i % 16)
    return words


class PlcServer:
    """The simulated PLC on Modbus TCP: `await start()`, `port`, `set_link(mode)`, `await stop()`."""

    def __init__(self, base: LandingBase, host: str = "127.0.0.1", port: int = 0) -> None:
        self.base = base
        self.host = host
        self.port = port
        self.link = LinkMode.NORMAL
        self._modbus: ModbusTcpServer | None = None
        self._inner_port = 0
        self._relay: asyncio.Server | None = None
        self._conns: set[asyncio.StreamWriter] = set()
        self._tasks: set[asyncio.Task[None]] = set()

    # --- model <-> registers -------------------------------------------------------------

    async def _action(
        self,
        func_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> None:
        """pymodbus hook: refresh a block from the model on reads, apply writes to it."""
        try:
            if values is not None:
                if func_code in (5, 15):
                    self.base.write_coils(address, [bool(v) for v in values])
                elif func_code in (6, 16):
                    self.base.write_holding(address, [int(v) for v in values], time.monotonic())
                return
            block = _BIT_FCS.get(func_code) or _REG_FCS.get(func_code)
            image: list[int]
            if block == "c":
                image = pack_bits(self.base.coils())
            elif block == "d":
                image = pack_bits(self.base.discrete_inputs())
            elif block == "i":
                # the heartbeat is the PLC's own scan counter: current at every read, not only
                # when the world's step loop last ran (a stall in this process would freeze it)
                self.base.tick_wall(time.monotonic())
                image = self.base.input_registers()
            elif block == "h":
                image = self.base.holding_registers()
            else:
                return
            registers[: len(image)] = image
        except Exception:  # bad input never takes the simulated PLC down
            log.exception("plc: error handling fc=%s address=%s", func_code, address)

    def _device(self) -> SimDevice:
        bits = DataType.BITS
        regs = DataType.REGISTERS
        return SimDevice(
            id=UNIT_ID,
            simdata=(
                [SimData(0, count=16 * ((N_COILS + 15) // 16), values=False, datatype=bits)],
                [SimData(0, count=16 * ((N_DISCRETE + 15) // 16), values=False, datatype=bits)],
                [SimData(0, count=N_HOLDING, values=0, datatype=regs)],
                [SimData(0, count=N_INPUT, values=0, datatype=regs)],
            ),
            action=self._action,
        )

    # --- lifecycle -----------------------------------------------------------------------

    async def start(self) -> None:
        """Start the Modbus server and the public relay; `port` holds the bound port after."""
        self._modbus = ModbusTcpServer(self._device(), address=("127.0.0.1", 0))
        await self._modbus.serve_forever(background=True)
        listener: Any = self._modbus.transport  # an asyncio.Server once listening
        self._inner_port = listener.sockets[0].getsockname()[1]
        self._relay = await asyncio.start_server(self._accept, self.host, self.port)
        self.port = self._relay.sockets[0].getsockname()[1]
        log.info("plc: Modbus TCP on %s:%d (unit %d)", self.host, self.port, UNIT_ID)

    async def stop(self) -> None:
        """Close every connection and both listeners."""
        if self._relay is not None:
            self._relay.close()
        self._close_all()
        await cancel_and_wait(list(self._tasks))
        if self._modbus is not None:
            await self._modbus.shutdown()
        if self._relay is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._relay.wait_closed(), 1.0)

    def set_link(self, mode: LinkMode | str) -> None:
        """Change the simulated link: normal, cut or freeze."""
        new = LinkMode(mode)
        old, self.link = self.link, new
        if new is LinkMode.CUT or (old is LinkMode.FREEZE and new is LinkMode.NORMAL):
            self._close_all()
        log.info("plc: link %s -> %s", old, new)

    def _close_all(self) -> None:
        for writer in list(self._conns):
            writer.close()
        self._conns.clear()

    # --- relay ---------------------------------------------------------------------------

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.link is LinkMode.CUT:
            writer.close()
            return
        self._conns.add(writer)
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self._inner_port)
        except OSError:
            writer.close()
            self._conns.discard(writer)
            return
        down = asyncio.ensure_future(self._pipe(up_reader, writer))
        self._tasks.add(down)
        try:
            await self._pipe(reader, up_writer)
        finally:
            down.cancel()
            self._tasks.discard(down)
            up_writer.close()
            writer.close()
            self._conns.discard(writer)

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while data := await reader.read(4096):
                if self.link is not LinkMode.NORMAL:
                    continue  # frozen: swallow requests and answers alike
                writer.write(data)
                await writer.drain()
        except (ConnectionError, OSError, asyncio.CancelledError):
            pass
