"""What the agent does with a vehicle it holds outside a landing loop: the vehicle a restarted
agent first finds (resume.py decides), and an abandoned landing's hold at the safe height.

- `HoldWatch.act_on_first_sight`: the landing a predecessor was flying (kept `flying`) is
  handed back (LAND), an abandoned one (kept `holding`) left holding for the operator; anything
  else is forgotten.
- `HoldWatch.check`: while the vehicle holds in GUIDED where the landing was abandoned (kept
  `holding`, by this agent or a predecessor), a failsafe the autopilot reports hands LAND back.
  ArduPilot's battery failsafe with BATT_FS_LOW_ACT none (its default) changes no mode, only
  the HEARTBEAT says CRITICAL: left in the hold the vehicle would hover until its battery gave
  out. It lands where it is, over the agent's last estimate of the pad; the landing loop that
  starts with the descent sends LANDING_TARGETs, and its takeover takes nothing from a failsafe
  (takeover.py).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from asset_agent.precland.resume import HOLDING, Decision, TakeoverRecord
from asset_agent.precland.takeover import hand_back
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

Sleep = Callable[[float], Awaitable[None]]


class HoldWatch:
    """A restarted agent's first look (`act_on_first_sight`), and LAND handed back from an
    abandoned landing's hold on a failsafe (`check()` each step)."""

    def __init__(self, autopilot: Any, record: TakeoverRecord, sleep_fn: Sleep) -> None:
        self.autopilot = autopilot
        self.record = record
        self.sleep_fn = sleep_fn
        self.task: asyncio.Task[None] | None = None  # the hand-back, once started

    async def act_on_first_sight(self, decision: Decision) -> None:
        """A restarted agent's first look at the vehicle, or a disarm ("none"): hand the landing
        it finds its predecessor flying back to the autopilot (kept as flying until this
        landing's takeover says otherwise, or the disarm), leave an abandoned one holding;
        otherwise forget what was kept."""
        try:
            if decision == "resume":
                log.warning("precland: the previous agent was flying the landing (GUIDED): LAND")
                await hand_back(self.autopilot, self.sleep_fn)
            elif decision == "hold":
                log.warning("precland: the previous agent abandoned the landing: left holding")
            else:
                await self.record.keep(None)
        except Exception:  # a refused mode change, the state file: the autopilot holds it
            log.exception("precland: the landing the previous agent flew was not handed back")

    def check(self, state: Any, flying: bool) -> None:
        """`flying`: a takeover of this agent holds the vehicle (its own rules apply)."""
        if self.task is not None and not self.task.done():
            return
        if self.record.current != HOLDING or flying:
            return
        if state.failsafe and state.armed and state.mode == "GUIDED":
            self.task = asyncio.create_task(self._land())

    async def _land(self) -> None:
        log.warning("precland: a failsafe while holding the abandoned landing: LAND handed back")
        try:
            await hand_back(self.autopilot, self.sleep_fn)
        except Exception:  # another mode (a pilot's), or disarmed: no longer ours either way
            log.exception("precland: LAND from the hold not taken")
        try:
            await self.record.keep(None)
        except Exception:
            log.exception("precland: the end of the hold not kept")

    async def close(self) -> None:
        await cancel_and_wait([self.task])
