"""The master side of the PLC watchdog: write a changing value to holding register 0."""

from __future__ import annotations

import asyncio
import logging

from base_station.plc.client import PlcClient, PlcLinkError
from base_station.plc.registers import HoldingRegister

log = logging.getLogger(__name__)


class WatchdogWriter:
    """Writes an incrementing counter every `period_s` (<= 0.5 s) while the link is up.

    `pause()` stops feeding the watchdog without closing anything: it is how a test
    stands for a frozen daemon (the PLC must then stop motion and latch fault 16).
    """

    def __init__(self, client: PlcClient, period_s: float = 0.25) -> None:
        if not 0 < period_s <= 0.5:
            raise ValueError("watchdog period must be in (0, 0.5] s")
        self.client = client
        self.period_s = period_s
        self.value = 0
        self.paused = False
        self.writes = 0

    def pause(self) -> None:
        """Stop feeding the watchdog (simulates a frozen master)."""
        self.paused = True

    def resume(self) -> None:
        """Feed the watchdog again."""
        self.paused = False

    async def run(self) -> None:
        """Feed forever; link errors are ignored here (the coordinator reports them)."""
        while True:
            if self.paused or not self.client.connected:
                await asyncio.sleep(min(0.05, self.period_s))  # write as soon as connected
                continue
            self.value = (self.value + 1) & 0xFFFF
            try:
                await self.client.write_register(HoldingRegister.WATCHDOG, self.value)
                self.writes += 1
            except PlcLinkError as err:
                log.debug("watchdog write failed: %s", err)
            await asyncio.sleep(self.period_s)
