"""The rule that keeps the autopilot's own descent from landing blind on a poor fix.

In mode `landing_target` the autopilot lands by itself on our LANDING_TARGETs. Its target lost,
it goes on descending on its last estimate (ArduPilot: for PLND_TIMEOUT, then retries that need
a rangefinder, then lands vertically) — blind, on the GNSS's drift: on a 3D fix 6.5 cm/√s, the
marker failing below 3 m landed 11.4 / 24.1 cm off. `LossGuard` is that rule as a pure step,
driven by the daemon (takeover.py, over MAVLink) and by the evaluation's autopilot path alike:

- while the autopilot lands it watches: the companion sequence (sequence.py) is stepped on the
  agent's estimate, the pad "seen" while measured within `fusion.hold_s` (the agent sends
  LANDING_TARGETs as long);
- the pad lost (last measured) above the final stretch (`retry.blind_max_height_unfixed_m`; LAND
  goes on descending 0.5 m/s through the fusion's hold, so the height it is noticed at would let a
  loss at 0.9 m through) on a fix short of RTK fixed, or on any fix with the pad outside the
  acceptance cone (LAND would come down where the vehicle is: fused-wind8 seed 1012, held 30 cm
  up by the descent gate, swung 20 cm off by the gusts, lost the pad and landed 15.7 cm off):
  "take" the vehicle (GUIDED) and fly the sequence's cautious retry (pause, climb back above
  where the pad was last measured); in view again and inside the cone (the agent's approach
  flies it there): "land" (LAND again, the autopilot descends on the LANDING_TARGETs; handed
  back the moment the pad was in view, 0.3 m up, ArduPilot 3.7's LAND, which holds no descent
  for the target, came down 8.5 cm off in the external demo); the retries used up: on RTK
  fixed the sequence's blind descent is handed to LAND, otherwise its abort (climb to the safe
  height) and "hold" once there — the landing is abandoned ("aborted-climb");
- a blind descent the sequence holds outside the cone (the wind keeps the vehicle off the pad:
  at 12 m/s LAND came down 3.5 m off) is flown by the agent too, handed back to LAND once inside
  the cone, and abandoned the same way when held off for `retry.blind_hold_max_s` in all;
- otherwise (RTK fixed and over the pad, or the final stretch) the autopilot lands as it would,
  and the loss spends none of the sequence's retries (its pause starts over at each step);
- never once LAND is touching down (`TOUCHING_DOWN_M` from the seat): taken there, a vehicle
  blown off in the last second was held on the ground in GUIDED, then lifted off to the safe
  height when the wait timed out.
"""

from __future__ import annotations

from dataclasses import dataclass

from asset_agent.precland.config import PrecisionLandingConfig
from asset_agent.precland.control import (
    VelocitySetpoint,
    blind_allowed,
    cone_position,
    inside_cone,
)
from asset_agent.precland.kalman import Estimate
from asset_agent.precland.pipeline import VehicleState
from asset_agent.precland.sequence import LandingSequence

TAKE_STATES = ("pause", "climb", "abort")  # states in which the sequence would not descend
# LAND this close to the seat (above touchdown, by the estimate) is touching down: the guard does
# not take the vehicle there. ArduPilot's GUIDED idles on the ground only once its land detector
# has seen the touchdown (about a second): a climb sent before that lifts the vehicle off the pad.
TOUCHING_DOWN_M = 0.1


@dataclass(frozen=True)
class GuardAction:
    """What to do now: "watch" (the autopilot lands), "take" (switch to GUIDED, then fly
    `setpoint`), "fly" (`setpoint`), "land" (hand LAND back), "hold" (abandoned, at the safe
    height) or "landed"."""

    kind: str
    setpoint: VelocitySetpoint | None = None


class LossGuard:
    """One landing's guard; feed it `step()` at a steady rate once the pad has been measured."""

    def __init__(self, config: PrecisionLandingConfig) -> None:
        self.config = config
        search = config.search.model_copy(update={"acquire_s": 0.0})
        self.sequence = LandingSequence(config.control, config.retry, search, config.camera)
        self.flying = False  # the agent holds the vehicle
        self.losses: list[float] = []  # heights above touchdown it took the vehicle at
        self._updates = 0
        self._last_fresh: float | None = None

    @property
    def held(self) -> bool:
        """Abandoned and holding at the safe height: the landing is over."""
        return self.flying and self.sequence.holding_safe

    def step(self, now: float, updates: int, est: Estimate, state: VehicleState) -> GuardAction:
        """`updates`: the agent's filter's measurement count (a new one: the pad measured)."""
        fresh = updates > self._updates
        self._updates = updates
        if fresh:
            self._last_fresh = now
        if self._last_fresh is None:
            return GuardAction("watch")  # not measured yet: nothing to guard
        seen = now - self._last_fresh <= self.config.fusion.hold_s
        cmd = self.sequence.follow(now, seen, est, state, fresh)
        if cmd.state == "landed":
            return GuardAction("landed")
        # the sequence would not descend: nor may the autopilot (a blind descent waiting outside
        # the cone: LAND would come down where the wind has put the vehicle)
        wait = cmd.state in TAKE_STATES or self.sequence.waiting
        if self.flying:
            if self.sequence.holding_safe:
                return GuardAction("hold", cmd.setpoint)
            # handed back outside the cone LAND comes down where the vehicle is (ArduPilot 3.x
            # holds no descent for the target; 4.x only within PLND_XY_DIST_MAX, where set)
            if wait or not inside_cone(est.rel_ned, self.config.control):
                return GuardAction("fly", cmd.setpoint)
            self.flying = False  # in view again, or back over the pad: the autopilot lands
            return GuardAction("land")
        above = cone_position(est.rel_ned, self.config.control)[1]
        if wait and above > TOUCHING_DOWN_M and self._blind_unsafe(est, state):
            self.flying = True
            self.losses.append(round(above, 2))
            return GuardAction("take", cmd.setpoint)
        self.sequence.restart_pause(now)  # the autopilot lands through this loss: no retry spent
        return GuardAction("watch")

    def _blind_unsafe(self, est: Estimate, state: VehicleState) -> bool:
        """The autopilot's blind descent from here would land off the contacts: on a fix short
        of RTK fixed from above the final stretch (the fix's drift), or on any fix with the pad
        outside the acceptance cone (LAND descends where the vehicle is, not over the pad)."""
        if self.config.retry.blind_max_height_unfixed_m is None:  # the thesis: blind anywhere
            return False
        height = float(est.rel_ned[2])
        # LAND went on descending through the fusion's hold: blind since the last measurement
        if not blind_allowed(self.sequence.blind_from(height), state.gnss_fix, self.config.retry):
            return True
        return not inside_cone(est.rel_ned, self.config.control)
