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

After the hand-over the same rule guards the descent (`guard`, guard.py): on a fix short of RTK
fixed a pad lost above the final stretch is not left to the autopilot's blind descent; the agent
flies the cautious retry and, the retries used up, climbs and holds ("aborted-climb").

Each hold on the vehicle is kept in the daemon's state file before it is taken, and again when
it is handed back or abandoned (`keep`; resume.py), for an agent restarted in the middle of it.
The hand-back (`hand_back`) is sent again until the autopilot takes it: a vehicle left in GUIDED
hovers until its battery fails; so is the take (`take`) while the autopilot still lands by itself:
its LAND would go on descending blind.

A vehicle put in another mode by another is theirs (`_taken_from_us`): an operator's pause or
return through this agent, and, while the agent holds it, a pilot's ground station or a failsafe's
RTL or LAND (told by ArduPilot 4.x's HEARTBEAT at the mode change). The agent lets go: no more
setpoints, no hand-back or take over their mode, nothing kept for a restart (`taken_into`).

A failsafe the autopilot reports (`_left_to_the_failsafe`: HEARTBEAT system_status CRITICAL,
whatever its action) leaves the landing to the autopilot too: a search's or a retry's climb, or
a hold at the safe height, would spend a failing battery. Held in GUIDED (a failsafe whose action
is none, ArduPilot's default for the battery, changes no mode), LAND is handed back first.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Awaitable, Callable
from typing import Any

from asset_agent.autopilot.errors import AutopilotError
from asset_agent.precland.config import PrecisionLandingConfig
from asset_agent.precland.control import clip_xy, cone_position
from asset_agent.precland.guard import TOUCHING_DOWN_M, LossGuard
from asset_agent.precland.kalman import Estimate
from asset_agent.precland.pipeline import LandingPipeline, VehicleState
from asset_agent.precland.resume import FLYING, HOLDING
from asset_agent.precland.sequence import LandingSequence

log = logging.getLogger(__name__)

PERIOD_S = 0.1  # setpoints at 10 Hz of sensor time
OVER_PAD_M = 0.3  # the RTK fallback hands LAND over this close to the surveyed pad
MODE_WAIT_S = 3.0  # sensor seconds to see the autopilot report LAND
RETRY_S = 1.0  # sensor seconds between hand-backs (or takes) the autopilot did not take


def descending(state: Any) -> bool:
    """True when the armed autopilot is landing (LAND, or any final descent), at any height."""
    return bool(
        state.armed and (state.landed_state == "LANDING" or (state.mode == "LAND" and state.in_air))
    )


class Takeover:
    """One landing's search and fallback; `run()` is its task, `active` while the agent flies."""

    def __init__(
        self,
        autopilot: Any,
        pipeline: LandingPipeline,
        config: PrecisionLandingConfig,
        now_fn: Callable[[], float],
        sleep_fn: Callable[[float], Awaitable[None]],
        path: str | None = None,
        keep: Callable[[str | None], Awaitable[None]] | None = None,
    ) -> None:
        """`keep`: where the agent's hold on the vehicle is kept (resume.TakeoverRecord.keep)."""
        self.autopilot = autopilot
        self.pipeline = pipeline
        self.config = config
        self.now_fn = now_fn
        self.sleep_fn = sleep_fn
        self.active = False  # the agent holds the vehicle (GUIDED): keep the loop running
        self.path = path  # decided: precision, search-then-precision, ... (None: not yet)
        search = config.search.model_copy(update={"acquire_s": 0.0})  # waited for already
        self.sequence = LandingSequence(config.control, config.retry, search, config.camera)
        self.loss_guard: LossGuard | None = None  # after the hand-over (guard.py)
        self.keep = keep or _forget
        # since when (time.monotonic()) another's mode change means the vehicle is theirs: the
        # start, and each of our own mode changes once the autopilot has taken it
        self._since = time.monotonic()
        self._held = False  # the autopilot took our GUIDED, not handed back since
        self.taken_into: str | None = None  # the mode another put the vehicle in meanwhile
        self.failsafe = False  # the autopilot reported a failsafe: the landing is its own

    async def run(self) -> None:
        """Search unless decided (a first measurement within `acquire_s`, else search and fall
        back), then guard the autopilot's descent while it lands on the pad."""
        if self.path is None and self.config.search.enabled:
            await self.search()
        if (
            self.taken_into is None
            and self.path != "aborted-climb"
            and self.config.retry.blind_max_height_unfixed_m is not None
        ):
            await self.guard()  # it watches from the first sighting on

    async def search(self) -> None:
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
        try:
            if await self._take():  # else the autopilot's landing goes on, guarded
                await self._fly()
        finally:
            self.active = False

    async def guard(self) -> None:
        """While the autopilot lands: a pad lost too high on a fix short of RTK fixed is flown
        by the agent's own retry instead of the autopilot's blind descent (guard.py)."""
        guard = self.loss_guard = LossGuard(self.config)
        try:
            while True:
                now, state, est = await self._tick()
                if await self._taken_from_us() or await self._left_to_the_failsafe():
                    return
                act = guard.step(now, self.pipeline.kalman.updates, est, state)
                if act.kind == "landed":
                    return
                if act.kind == "take":
                    log.warning(
                        "precland: pad lost at %.1f m (no RTK fixed GNSS, or off the pad): "
                        "the agent flies the retry",
                        guard.losses[-1],
                    )
                    if not await self._take():  # its LAND goes on: watched to its end
                        if self.taken_into is not None or self.failsafe:
                            return
                        guard.flying = False
                        continue
                if act.setpoint is not None:
                    sp = act.setpoint
                    self.autopilot.send_velocity_ned(sp.vn, sp.ve, sp.vd)
                if act.kind == "land":
                    log.info(
                        "precland: %.3f m off the pad, %.2f m up (the agent's estimate): LAND again",
                        *cone_position(est.rel_ned, self.config.control),
                    )
                    await self._land()
                    self.active = False
                if act.kind == "hold":
                    await self.keep(HOLDING)
                    self.path = "aborted-climb"
                    log.warning("precland: %s: holding at a safe height", self.abort_reason)
                    return
        finally:
            self.active = False

    @property
    def holding(self) -> bool:
        """The agent flies the vehicle: the autopilot has taken its GUIDED (`active` is set from
        the take's first try on)."""
        return self.active and self._held

    @property
    def abort_reason(self) -> str | None:
        """Why the landing was abandoned (sequence.ABORT_REASONS), if it was."""
        guarded = self.loss_guard.sequence.abort_reason if self.loss_guard is not None else None
        return guarded or self.sequence.abort_reason

    @property
    def losses(self) -> list[float]:
        """Heights (above touchdown) at which the guard took the vehicle, this landing."""
        return self.loss_guard.losses if self.loss_guard is not None else []

    async def _take(self) -> bool:
        """Take the vehicle (GUIDED), kept first: a restart in the middle resumes the landing.
        False when the autopilot never took it and the landing is its own again (`take`)."""
        if await self._taken_from_us():  # an operator's mode since the landing began
            return False
        if await self._left_to_the_failsafe():
            return False
        await self.keep(FLYING)
        self.active = True
        if await take(self.autopilot, self.sleep_fn, self._not_touching_down):
            self._since, self._held = time.monotonic(), True
            return True
        await self.keep(None)
        self.active = False
        return False

    def _not_touching_down(self) -> bool:
        """Above the height where the guard takes the vehicle no more (guard.TOUCHING_DOWN_M)."""
        height = float(self.pipeline.kalman.estimate().rel_ned[2])
        return height - self.config.control.touchdown_height > TOUCHING_DOWN_M

    async def _land(self) -> None:
        """Hand the descent back (LAND), staying active until the autopilot reports it, so that
        the supervisor does not see a gap between our mode and the autopilot's landing."""
        self._held = False
        await hand_back(self.autopilot, self.sleep_fn)
        self._since = time.monotonic()
        await self.keep(None)
        for _ in range(round(MODE_WAIT_S / PERIOD_S)):
            if getattr(self.autopilot.state, "mode", None) == "LAND":
                return
            await self.sleep_fn(PERIOD_S)

    async def _fly(self) -> None:
        seen_before = self.pipeline.kalman.updates
        while True:
            now, state, est = await self._tick()
            if await self._taken_from_us() or await self._left_to_the_failsafe():
                return
            seen = self.pipeline.kalman.updates > seen_before
            seen_before = self.pipeline.kalman.updates
            cmd = self.sequence.follow(now, seen, est, state)
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
                    await self.keep(HOLDING)
                    self.path = "aborted-climb"
                    log.warning(
                        "precland: no pad found, no RTK fixed GNSS: holding at a safe height"
                    )
                    return

    async def _taken_from_us(self) -> bool:
        """Has another put the vehicle in another mode since the landing began, or since our own
        last mode change (an operator's command through this agent; while the agent holds the
        vehicle, also a pilot's ground station, a failsafe's RTL or LAND)? Then the vehicle is
        theirs: no setpoint, hand-back or take overrides them, what is kept is forgotten.
        A mode change sent through this adapter counts at once; one from elsewhere by the first
        HEARTBEAT handled after our take's COMMAND_ACK (sent after it on a link that keeps
        order, it carries the mode as it is since); while the autopilot lands by itself, the
        supervisor ends the landing loop as soon as a HEARTBEAT says it no longer does."""
        mode = self._changed_by_another()
        if mode is None:
            return False
        log.warning("precland: the vehicle was put in %s by another: it is left to them", mode)
        self.taken_into = mode
        self.active = self._held = False
        await self.keep(None)
        return True

    async def _left_to_the_failsafe(self) -> bool:
        """Does the autopilot report a failsafe (HEARTBEAT system_status CRITICAL or EMERGENCY:
        ArduPilot's any_failsafe_triggered, a battery's, radio's, GCS's or EKF's)? Then the
        landing is the autopilot's from here: no take for a search or a retry, no climb to the
        safe height. A vehicle the agent holds in GUIDED is handed LAND back (a failsafe that
        changed no mode); its own failsafe mode (LAND, RTL) is left as it is."""
        if not self.autopilot.state.failsafe:
            return False
        self.failsafe = True
        mode = self.autopilot.state.mode
        if self.active and mode == "GUIDED":
            log.warning("precland: the autopilot reports a failsafe: LAND handed back")
            await self._land()
        else:
            log.warning("precland: the autopilot reports a failsafe in %s: left to it", mode)
        self.active = self._held = False
        await self.keep(None)
        return True

    def _changed_by_another(self) -> str | None:
        """The mode another has put the vehicle in since `_since`, if any (`_taken_from_us`)."""
        changed_at, mode = self.autopilot.mode_changed
        if changed_at > self._since:  # through this adapter
            return str(mode)
        heard, state = self.autopilot.heartbeat_at, self.autopilot.state
        if self.holding and heard is not None and heard > self._since and state.mode != "GUIDED":
            return str(state.mode)
        return None

    async def _tick(self) -> tuple[float, VehicleState, Estimate]:
        """The next step, PERIOD_S of sensor time on, once the autopilot's state is known: the
        time, that state and the filter's estimate."""
        while True:
            await self.sleep_fn(PERIOD_S)
            now = self.now_fn()
            state = self.pipeline.state_at(now)
            if state is not None:
                return now, state, self.pipeline.kalman.estimate()


async def _forget(value: str | None) -> None:
    """`keep` for a takeover whose daemon keeps nothing (the evaluation, tests)."""


async def insist(
    autopilot: Any,
    sleep_fn: Callable[[float], Awaitable[None]],
    mode: str,
    keep_trying: Callable[[Any], bool],
) -> int:
    """`mode`, sent again every RETRY_S while the autopilot has not taken it (no COMMAND_ACK, the
    link down, a refusal). Done when acknowledged, or when a HEARTBEAT heard since the first try
    reports the mode (an answer lost; an older one may tell a mode left since, unheard while the
    link is down): returns the tries. Raises the last error once `keep_trying(state)` says no."""
    tries, first = 0, time.monotonic()
    while True:
        tries += 1
        try:
            await autopilot.set_mode(mode)
            return tries
        except AutopilotError as err:
            state, heard = autopilot.state, autopilot.heartbeat_at
            if state.mode == mode and heard is not None and heard > first:
                return tries
            if not keep_trying(state):
                log.warning(
                    "precland: %s not taken (%s), the vehicle %s in %s: given up",
                    mode,
                    err,
                    "armed" if state.armed else "disarmed",
                    state.mode,
                )
                raise
            log.warning("precland: %s not taken (%s): sending it again", mode, err)
        await sleep_fn(RETRY_S)


async def take(
    autopilot: Any, sleep_fn: Callable[[float], Awaitable[None]], wanted: Callable[[], bool]
) -> bool:
    """GUIDED, insisted on while the autopilot still lands by itself: left to it, its LAND would
    descend blind, what the take is there to stop. False (the landing is the autopilot's) once
    `wanted()` says no more (touching down) or the vehicle is known (link up) not to be landing
    by itself (landed, disarmed, a pilot's mode)."""

    def landing_by_itself(state: Any) -> bool:
        return (descending(state) or not state.link_up) and wanted()

    try:
        await insist(autopilot, sleep_fn, "GUIDED", landing_by_itself)
    except AutopilotError:
        return False
    return True


async def hand_back(autopilot: Any, sleep_fn: Callable[[float], Awaitable[None]]) -> int:
    """LAND, insisted on while the vehicle may still fly in GUIDED: left there, it would hover
    until its battery fails. Gives up (raises) once the vehicle is known (link up) not to be the
    agent's any more (disarmed, or another mode: a pilot took it). Returns the number of tries."""

    def still_ours(state: Any) -> bool:
        return not state.link_up or (state.armed and state.mode == "GUIDED")

    return await insist(autopilot, sleep_fn, "LAND", still_ours)
