"""The autopilot parameters the agent changes for a landing, given back when the landing ends.

ArduPilot saves every PARAM_SET to its storage (AP_Param `set_and_save`): a value the agent sets
for one landing (PLND_XY_DIST_MAX 0.05 m, the descent gate: readiness.py) outlives the landing,
a reboot and the agent. A later landing the agent does not supervise (the agent stopped, a
pilot's LAND) would then hold its descent until its target estimate was within 5 cm. So each
parameter's value from before the agent first changed it is kept in the daemon's state file
(`Memory`, as resume.py keeps the takeover), committed before the PARAM_SET goes, and set back
once the phase is over: no landing loop of the agent's runs and the vehicle is not descending
(landed, the landing abandoned at its safe height, the vehicle in someone else's mode). A
landing in progress keeps what it flies by; a failsafe's LAND is restored after it lands.

An agent killed in the middle of a landing leaves the record behind: the next one reads it at
start, keeps it through a landing it finds in progress (its own gate sets the same value again,
the record keeps the original) and restores it the same way.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from typing import Any

from asset_agent.autopilot.params import MAV_PARAM_TYPE_REAL32, read_param, set_param
from asset_agent.precland.resume import Memory, known
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

KEY = "autopilot.params.changed"  # {name: [value before the agent changed it, MAV_PARAM_TYPE]}
RETRY_S = 5.0  # a restore that failed (the link down) is tried again this much later


class ParamLedger:
    """Parameters changed for the current phase and their values from before (`changed`)."""

    def __init__(self, autopilot: Any, memory: Memory | None = None) -> None:
        self.autopilot = autopilot
        self.memory = memory
        self.changed: dict[str, tuple[float, int]] = {}
        self._lock = asyncio.Lock()  # a restore and a landing's change in the order asked
        self._task: asyncio.Task[None] | None = None
        self._retry_at = 0.0

    @property
    def settled(self) -> bool:
        """Nothing changed is left to restore, and no restore is under way."""
        return not self.changed and (self._task is None or self._task.done())

    async def load(self) -> None:
        """What an agent before this one changed and did not give back."""
        if self.memory is None:
            return
        raw = await self.memory.recall(KEY)
        if raw:
            self.changed = {name: (float(v), int(k)) for name, (v, k) in json.loads(raw).items()}
            log.warning("precland: the previous agent left parameters changed: %s", self.changed)

    async def _keep(self) -> None:
        if self.memory is not None:
            kept = json.dumps({n: list(v) for n, v in self.changed.items()})
            await self.memory.remember(KEY, kept if self.changed else None)

    async def change(
        self, name: str, value: float, param_type: int = MAV_PARAM_TYPE_REAL32
    ) -> float:
        """Set `name` for this phase, its value from before kept (and committed) first; the
        value the autopilot now holds."""
        async with self._lock:
            if name not in self.changed:
                before = await read_param(self.autopilot, name)
                if math.isclose(before, value, rel_tol=1e-6, abs_tol=1e-6):
                    return before
                self.changed[name] = (before, param_type)
                await self._keep()
            return await set_param(self.autopilot, name, value, param_type)

    async def restore(self) -> None:
        """Every changed parameter back to its value from before, each forgotten once set."""
        async with self._lock:
            for name, (value, kind) in list(self.changed.items()):
                await set_param(self.autopilot, name, value, kind)
                del self.changed[name]
                await self._keep()
                log.info("precland: %s restored to %g", name, value)

    def check(self, state: Any, busy: bool) -> None:
        """Each supervision step: restore once the phase is over (`busy`: a landing loop of the
        agent's runs, the vehicle descends, or the first look is not done)."""
        if not self.changed or busy or not known(state):  # a descent not yet heard of
            return
        if self._task is not None and not self._task.done():
            return
        if time.monotonic() < self._retry_at:
            return
        self._task = asyncio.create_task(self._restore(), name="precland-params-restore")

    async def _restore(self) -> None:
        try:
            await self.restore()
        except Exception:  # the link, the state file: kept, tried again
            self._retry_at = time.monotonic() + RETRY_S
            log.exception("precland: changed parameters not restored yet")

    async def close(self) -> None:
        """Stop a restore under way (what is not restored stays kept for the next agent)."""
        await cancel_and_wait([self._task])
