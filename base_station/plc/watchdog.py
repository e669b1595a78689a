"""The master side of the PLC watchdog: write a changing value to holding register 0.

The spec (plc-modbus.md, holding register 0): a value unchanged for 2 s makes the PLC stop all
motion and latch fault 16, which stays latched (and refuses every motion) until FAULT_RESET.
`recoverable_latch` says when the daemon may clear it itself: see its docstring.
"""

from __future__ import annotations

import asyncio
import logging
import time

from base_station.plc.client import PlcClient, PlcLinkError
from base_station.plc.codec import PlcState
from base_station.plc.registers import MOTION_BLOCKING_FAULTS, FaultBit, HoldingRegister

log = logging.getLogger(__name__)

# the spec's bound on the feeding period: fed within this, the PLC sees a live master
FED_WITHIN_S = 0.5


def recoverable_latch(state: PlcState) -> bool:
    """True when the watchdog fault is the only latched fault and the E-stop is released.

    FAULT_RESET clears every latched fault, so it is written only then: a stall or an E-stop
    needs a person, a watchdog latch only needs its master back. Clearing it moves nothing.
    """
    latched = state.fault_bits & MOTION_BLOCKING_FAULTS
    return latched == FaultBit.WATCHDOG and not state.estop_active


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
        self.last_write_at: float | None = None  # monotonic time of the last acknowledged write

    def pause(self) -> None:
        """Stop feeding the watchdog (simulates a frozen master)."""
        self.paused = True

    def resume(self) -> None:
        """Feed the watchdog again."""
        self.paused = False

    def fed(self, now: float | None = None) -> bool:
        """Whether the PLC has had a new value within the spec's 500 ms (a live master)."""
        at = self.last_write_at
        now = time.monotonic() if now is None else now
        return not self.paused and at is not None and now - at <= FED_WITHIN_S

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
                self.last_write_at = time.monotonic()
            except PlcLinkError as err:
                log.debug("watchdog write failed: %s", err)
            await asyncio.sleep(self.period_s)
