"""The daemon's search before it hands the descent to the autopilot (mode `landing_target`).

The autopilot lands by itself on our LANDING_TARGETs (ArduPilot's PLND); with no target it lands
on its GNSS alone, blind. So when the landing loop starts and no source has measured the pad
within `search.acquire_s`, the agent takes the vehicle (GUIDED) and flies the companion sequence's
own search (sequence.py, search.py: the same expanding square at this height) by velocity
setpoints, with the same rule after it:

- the pad comes into view: LAND again, and the autopilot descends on the LANDING_TARGETs
  ("search-then-precision");
- the search is over on an RTK fixed GNSS: fly over the surveyed pad, then LAND — on its RTK
  GNSS, and on the LANDING_TARGETs as soon as the pad is in view ("rtk-fallback");
- otherwise: climb to the safe height and hold there, reporting it ("aborted-climb") — never a
  blind landing on a float or plain fix.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Awaitable, Callable
from typing import Any

from asset_agent.precland.config import PrecisionLandingConfig
from asset_agent.precland.control import clip_xy
from asset_agent.precland.pipeline import LandingPipeline
from asset_agent.precland.sequence import LandingSequence

log = logging.getLogger(__name__)

PERIOD_S = 0.1  # setpoints at 10 Hz of sensor time
OVER_PAD_M = 0.3  # the RTK fallback hands LAND over this close to the surveyed pad
MODE_WAIT_S = 3.0  # sensor seconds to see the autopilot report LAND


class Takeover:
    """One landing's search and fallback; `run()` is its task, `active` while the agent flies."""

    def __init__(
        self,
        autopilot: Any,
        pipeline: LandingPipeline,
        config: PrecisionLandingConfig,
        now_fn: Callable[[], float],
        sleep_fn: Callable[[float], Awaitable[None]],
    ) -> None:
        self.autopilot = autopilot
        self.pipeline = pipeline
        self.config = config
        self.now_fn = now_fn
        self.sleep_fn = sleep_fn
        self.active = False  # the agent holds the vehicle (GUIDED): keep the loop running
        self.path: str | None = None  # decided: precision, search-then-precision, ...
        search = config.search.model_copy(update={"acquire_s": 0.0})  # waited for already
        self.sequence = LandingSequence(config.control, config.retry, search, config.camera)

    async def run(self) -> None:
        """Wait for a first measurement; without one, search and fall back."""
        start = self.now_fn()
        while self.now_fn() - start < self.config.search.acquire_s:
            if self.pipeline.kalman.updates:
                self.path = "precision"
                return
            await self.sleep_fn(PERIOD_S)
        if self.pipeline.kalman.updates:
            self.path = "precision"
            return
        log.info("precland: the pad is not in view: searching")
        await self.autopilot.set_mode("GUIDED")
        self.active = True
        try:
            await self._fly()
        finally:
            self.active = False

    async def _land(self) -> None:
        """Hand the descent back (LAND), staying active until the autopilot reports it, so that
        the supervisor does not see a gap between our mode and the autopilot's landing."""
        await self.autopilot.set_mode("LAND")
        for _ in range(round(MODE_WAIT_S / PERIOD_S)):
            if getattr(self.autopilot.state, "mode", None) == "LAND":
                return
            await self.sleep_fn(PERIOD_S)

    async def _fly(self) -> None:
        seen_before = self.pipeline.kalman.updates
        while True:
            now = self.now_fn()
            state = self.pipeline.state_at(now)
            if state is None:
                await self.sleep_fn(PERIOD_S)
                continue
            est = self.pipeline.kalman.estimate()
            seen = self.pipeline.kalman.updates > seen_before
            seen_before = self.pipeline.kalman.updates
            cmd = self.sequence.step(
                now,
                seen,
                est.rel_ned,
                est.heading,
                state.position_ned,
                state.attitude[2],
                gnss_fix=state.gnss_fix,
            )
            if cmd.state in ("recentre", "approach"):  # found: the autopilot lands on it
                self.path = "search-then-precision"
                await self._land()
                return
            if cmd.state == "fallback":
                if math.hypot(est.rel_ned[0], est.rel_ned[1]) <= OVER_PAD_M:
                    self.path = "rtk-fallback"
                    await self._land()
                    return
                c = self.config.control
                vn, ve = clip_xy(
                    c.kp_xy * est.rel_ned[0], c.kp_xy * est.rel_ned[1], self.config.search.speed
                )
                self.autopilot.send_velocity_ned(vn, ve, 0.0)
            else:  # search, or abort (climbing, then holding)
                sp = cmd.setpoint
                self.autopilot.send_velocity_ned(sp.vn, sp.ve, sp.vd)
                if self.sequence.holding_safe:
                    self.path = "aborted-climb"
                    log.warning(
                        "precland: no pad found, no RTK fixed GNSS: holding at a safe height"
                    )
                    return
            await self.sleep_fn(PERIOD_S)
