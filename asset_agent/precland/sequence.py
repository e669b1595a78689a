"""The landing sequence with the thesis's cautious retries, as a table-driven state machine.

approach ─lost→ pause (cautious, attempts left) or blind  pause ─target→ recentre
pause ─timeout→ climb (attempts left) or blind             climb ─target→ recentre
  (blind: on RTK fixed, or low enough; else abort)
climb ─reached→ pause                                      blind ─target→ approach
blind ─held off the cone too long→ abort
recentre ─centred→ approach                                recentre ─lost→ pause or blind
approach ─unseen→ acquire (never seen yet)                 acquire ─target→ recentre
acquire ─timeout→ search                                   search ─target→ recentre
search ─over→ fallback (RTK fixed) or abort                fallback ─target→ approach
fallback ─fix lost→ abort                                  any ─touchdown→ landed

A pad never seen is searched for (search.py) at the approach altitude; when the search is over
without it, the fallback lands on the GNSS over the surveyed pad only on an RTK fixed fix and
otherwise climbs to a safe height and holds there ("abort"), never landing blind on a float or
plain fix. The same rule ends the cautious retries: a target lost for the last time (no retry
left) is descended on blind only on an RTK fixed fix or from the final stretch
(`retry.blind_max_height_unfixed_m`); higher up on a float or plain fix the blind seconds would
be flown on its drift (4.6 and 6.5 cm/√s: a loss at 3 m landed 8 and 12 cm off), so it aborts.
`path` says which way the landing went.

Climbing goes back to where the target was last *measured* (its horizontal position, and its
height plus a margin, since whatever lost it at that height may lose it there again; a value the
fusion merely holds does not count), or straight up to a default height when it was
never seen. Re-centring hovers there until the vision has been fresh for a while and the vehicle
is over the pad, so the next descent through the failing zone starts from a converged estimate.
Blind descent keeps steering towards the Kalman estimate; after losing a target it had seen (the
height then comes from vision) it descends fast and flares to the blind descent speed near the
ground, since the estimate drifts with time, not with height. Within `blind_wait_height_m` of
touchdown, on an estimate worth waiting on (RTK fixed, or a recent sighting), it keeps to the
approach's cone: outside it, it slows to the cone's surface and holds the final stretch, and if
the wind keeps it outside for `blind_hold_max_s` it aborts rather than land beside the pad.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from asset_agent.precland.config import CameraModel, ControlConfig, RetryConfig, SearchConfig
from asset_agent.precland.control import (
    HOVER,
    VelocitySetpoint,
    allowed_pos_error,
    blind_allowed,
    blind_profile,
    clip_xy,
    cone_position,
    cone_setpoint,
    held_off_centre,
    inside_cone,
)
from asset_agent.precland.kalman import Estimate, rtk_fixed
from asset_agent.precland.search import ExpandingSquare

if TYPE_CHECKING:
    from asset_agent.precland.pipeline import VehicleState

log = logging.getLogger(__name__)

TRANSITIONS: dict[tuple[str, str], str] = {
    ("approach", "lost"): "pause",
    ("approach", "lost_default"): "blind",
    ("pause", "target"): "recentre",
    ("pause", "retry"): "climb",
    ("pause", "give_up"): "blind",
    ("climb", "target"): "recentre",
    ("climb", "reached"): "pause",
    ("recentre", "centred"): "approach",
    ("recentre", "lost"): "pause",
    ("recentre", "lost_default"): "blind",
    ("approach", "abort"): "abort",
    ("recentre", "abort"): "abort",
    ("pause", "abort"): "abort",
    ("blind", "target"): "approach",
    ("approach", "touchdown"): "landed",
    ("blind", "touchdown"): "landed",
    ("pause", "touchdown"): "landed",
    ("climb", "touchdown"): "landed",
    ("recentre", "touchdown"): "landed",
    ("approach", "unseen"): "acquire",
    ("acquire", "target"): "recentre",
    ("acquire", "search"): "search",
    ("search", "target"): "recentre",
    ("search", "rtk_fallback"): "fallback",
    ("search", "abort"): "abort",
    ("fallback", "target"): "approach",
    ("fallback", "abort"): "abort",
    ("blind", "abort"): "abort",
    ("acquire", "touchdown"): "landed",
    ("search", "touchdown"): "landed",
    ("fallback", "touchdown"): "landed",
}
ABORT_REASONS = {
    "search": "pad not found, no RTK fix",
    "fallback": "RTK fix lost on the way down",
    "blind": "held off the pad by the wind",
}  # by the state it left; else "pad lost"
PATHS = ("precision", "search-then-precision", "rtk-fallback", "aborted-climb", "gnss")


@dataclass(frozen=True)
class Command:
    """What the controller asks for now: its state, the setpoint, and the attempts used."""

    state: str
    setpoint: VelocitySetpoint
    attempts: int


class LandingSequence:
    """Feeds on (target seen?, estimate, vehicle position) and returns velocity setpoints."""

    def __init__(
        self,
        control: ControlConfig | None = None,
        retry: RetryConfig | None = None,
        search: SearchConfig | None = None,
        camera: CameraModel | None = None,
    ) -> None:
        self.control = control or ControlConfig()
        self.retry = retry or RetryConfig()
        self.search = search or SearchConfig()
        self.camera = camera or CameraModel()
        self.state = "approach"
        self._square: ExpandingSquare | None = None  # the search, once started
        self._fallback = False
        self._height = 0.0
        self.attempts = 0
        self._since = 0.0
        # the last fresh sighting: vehicle n, e, height, and when (sensor clock)
        self._last_seen: tuple[float, float, float, float] | None = None
        self._goal: tuple[float, float, float] | None = None
        self._integral = (0.0, 0.0)  # integral of the horizontal error (m·s) while approaching
        self._last_t: float | None = None
        self._gnss_fix: int | None = None
        self.abort_reason: str | None = None  # ABORT_REASONS, once aborted
        self._held_s = 0.0  # how long a blind descent has waited outside the cone
        self.waiting = False  # blind and waiting outside the cone: nobody may descend

    @property
    def path(self) -> str:
        """Which way the landing went: "precision" (the pad in view on the approach),
        "search-then-precision", "rtk-fallback" (searched in vain, descended on RTK fixed GNSS),
        "aborted-climb" (searched in vain, or lost for the last time too high without RTK fixed,
        or held off the pad by the wind: climbing or holding), or "gnss" (never saw the pad,
        search off)."""
        if self.state == "abort":
            return "aborted-climb"
        if self._fallback:
            return "rtk-fallback"
        if self._last_seen is None:
            return "gnss"
        return "search-then-precision" if self._square is not None else "precision"

    def blind_from(self, a: float) -> float:
        """Height above touchdown a blind descent began at, the vehicle `a` above the pad now:
        where the pad was last measured, whatever the vehicle did while the fusion held it."""
        seen = a if self._last_seen is None else max(a, self._last_seen[2])
        return seen - self.control.touchdown_height

    @property
    def holding_safe(self) -> bool:
        """Aborted and up at the safe height: the landing is over, for the operator to decide."""
        tol = self.retry.reached_tolerance_m
        return self.state == "abort" and self._height >= self.search.abort_height_m - tol

    def restart_pause(self, now: float) -> None:
        """A loss somebody else flies through (the autopilot's own landing, guard.py): its pause
        starts over, so it spends no retry; the retries stay for the losses this sequence flies."""
        if self.state == "pause":
            self._since = now

    def _fire(self, event: str, now: float) -> None:
        nxt = TRANSITIONS.get((self.state, event))
        if nxt is None:
            return
        if nxt == "abort" and self.state != "abort":
            self.abort_reason = ABORT_REASONS.get(self.state, "pad lost, no RTK fix")
        log.info("landing %s -%s-> %s (attempts %d)", self.state, event, nxt, self.attempts)
        self.state, self._since = nxt, now

    def step(
        self,
        now: float,
        target_seen: bool,
        rel_ned,
        pad_heading: float | None,
        vehicle_ned,
        yaw: float,
        fresh: bool | None = None,
        gnss_fix: int | None = None,
    ) -> Command:
        """One control step. `rel_ned` is the filter's estimate (pad minus vehicle, NED),
        `vehicle_ned` the autopilot's local position; `fresh` says the target is a new
        measurement, not one the fusion holds (default: `target_seen`); `gnss_fix` is the
        autopilot's GNSS fix type (GPS_RAW_INT; None: unknown, not RTK fixed)."""
        a = float(rel_ned[2])
        self._height = a
        self._gnss_fix = gnss_fix
        fresh = target_seen if fresh is None else fresh
        dt = 0.0 if self._last_t is None else max(0.0, min(now - self._last_t, 0.5))
        self._last_t = now
        held = self.state == "blind" and self._blind_off_cone(now, rel_ned)
        if held:
            self._held_s += dt
        if self.state == "landed":
            return Command("landed", VelocitySetpoint(0, 0, 0, land=True), self.attempts)
        low = a <= self.control.touchdown_height + self.control.land_margin
        off = (
            self.state == "approach"
            and held_off_centre(
                float(rel_ned[0]),
                float(rel_ned[1]),
                a - self.control.touchdown_height,
                self.control,
            )
        ) or held
        if low and self.state != "abort" and not off:
            self._fire("touchdown", now)
            return Command(
                self.state,
                VelocitySetpoint(0, 0, self.control.slow_descent, land=True),
                self.attempts,
            )
        if fresh:
            self._last_seen = (float(vehicle_ned[0]), float(vehicle_ned[1]), a, now)
        if target_seen:
            self._fire("target", now)  # from pause, climb, blind; elsewhere no transition
            if self.state == "recentre" and self._centred(now, fresh, rel_ned):
                self._fire("centred", now)
        elif self.state == "approach" and self._last_seen is None and self.search.enabled:
            self._fire("unseen", now)  # never seen: hover at the approach altitude, then search
        elif self.state in ("approach", "recentre"):
            # cautious: pause and retry while attempts remain; the last loss goes blind at once
            # (another pause would only let the GNSS drift grow before the same blind descent)
            retry = self.retry.cautious and self.attempts < self.retry.max_attempts
            self._fire("lost" if retry else self._blind_or_abort("lost_default", a, gnss_fix), now)
        elif self.state == "acquire" and now - self._since >= self.search.acquire_s:
            centre = (float(vehicle_ned[0] + rel_ned[0]), float(vehicle_ned[1] + rel_ned[1]))
            self._square = ExpandingSquare.start(now, centre, a, self.camera, self.search)
            self._fire("search", now)
        elif self.state == "search" and self._waypoint(now, vehicle_ned) is None:
            rtk = rtk_fixed(gnss_fix) and self.search.rtk_fallback
            self._fallback = rtk
            self._fire("rtk_fallback" if rtk else "abort", now)
        elif self.state == "blind" and self._held_s > self.retry.blind_hold_max_s:
            self._fire("abort", now)  # the wind holds it off the pad: climb, not land beside it
        elif self.state == "fallback" and not rtk_fixed(gnss_fix):
            self._fire("abort", now)  # the fix degraded on the way down: not blind on it
        elif self.state == "pause" and now - self._since >= self.retry.pause_s:
            if self.attempts < self.retry.max_attempts:
                self.attempts += 1
                self._goal = self._climb_goal(vehicle_ned, a)
                self._fire("retry", now)
            else:
                self._fire(self._blind_or_abort("give_up", a, gnss_fix), now)
        elif self.state == "climb" and (
            self._reached(vehicle_ned, a) or now - self._since >= self.retry.climb_timeout_s
        ):  # or the wind will not let it get there: pause where it is (no climb without end)
            self._fire("reached", now)
        self.waiting = self.state == "blind" and self._blind_off_cone(now, rel_ned)
        return Command(
            self.state,
            self._setpoint(now, rel_ned, pad_heading, vehicle_ned, yaw, dt),
            self.attempts,
        )

    def follow(
        self, now: float, seen: bool, est: Estimate, state: VehicleState, fresh: bool | None = None
    ) -> Command:
        """`step` on the filter's estimate and the autopilot's latest state."""
        return self.step(
            now,
            seen,
            est.rel_ned,
            est.heading,
            state.position_ned,
            state.attitude[2],
            fresh=fresh,
            gnss_fix=state.gnss_fix,
        )

    def _blind_or_abort(self, event: str, a: float, gnss_fix: int | None) -> str:
        """`event` (on to the blind descent) when a blind landing is allowed here, else "abort":
        after a sighting, blind only on RTK fixed or when the pad was last measured within
        `blind_max_height_unfixed_m` of touchdown. A pad never seen (the search off) is the
        operator's choice: blind."""
        if self._last_seen is None:
            return event
        return event if blind_allowed(self.blind_from(a), gnss_fix, self.retry) else "abort"

    def _waypoint(self, now: float, vehicle_ned) -> tuple[float, float] | None:
        assert self._square is not None
        return self._square.target(now, (float(vehicle_ned[0]), float(vehicle_ned[1])))

    def _centred(self, now: float, fresh: bool, rel_ned) -> bool:
        """Re-centring is done: vision fresh and the vehicle over the pad after settling, or
        the time allowed for it is up; at once when off or before the first retry."""
        r = self.retry
        if not r.recentre or self.attempts == 0 or now - self._since >= r.recentre_timeout_s:
            return True
        over = math.hypot(float(rel_ned[0]), float(rel_ned[1])) <= r.recentre_tolerance_m
        return fresh and over and now - self._since >= r.recentre_settle_s

    def _climb_goal(self, vehicle_ned, a: float) -> tuple[float, float, float]:
        if self._last_seen is not None:
            n, e, h, _ = self._last_seen
            return n, e, max(h + self.retry.climb_margin_m, a)
        return float(vehicle_ned[0]), float(vehicle_ned[1]), max(self.retry.default_height, a)

    def _reached(self, vehicle_ned, a: float) -> bool:
        assert self._goal is not None
        n, e, h = self._goal
        tol = self.retry.reached_tolerance_m
        return math.hypot(vehicle_ned[0] - n, vehicle_ned[1] - e) <= tol and a >= h - tol

    def _integrate(self, sp: VelocitySetpoint, rel_ned, dt: float) -> VelocitySetpoint:
        """Add the integral term (anti-windup: clamped to max_integral_speed)."""
        c = self.control
        if c.ki_xy <= 0 or sp.land:
            return sp
        lim = c.max_integral_speed / c.ki_xy
        i_n = max(-lim, min(lim, self._integral[0] + float(rel_ned[0]) * dt))
        i_e = max(-lim, min(lim, self._integral[1] + float(rel_ned[1]) * dt))
        self._integral = (i_n, i_e)
        vn, ve = clip_xy(sp.vn + c.ki_xy * i_n, sp.ve + c.ki_xy * i_e, c.max_speed_xy)
        return VelocitySetpoint(vn, ve, sp.vd, sp.yaw_rate, sp.land)

    def _setpoint(
        self, now: float, rel_ned, pad_heading, vehicle_ned, yaw, dt: float
    ) -> VelocitySetpoint:
        c = self.control
        if self.state == "approach":
            sp = cone_setpoint(rel_ned, pad_heading, yaw, c)
            return self._integrate(sp, rel_ned, dt)
        if self.state == "recentre":  # centre over the pad at this height
            sp = cone_setpoint(rel_ned, pad_heading, yaw, c)
            sp = self._integrate(sp, rel_ned, dt)
            return VelocitySetpoint(sp.vn, sp.ve, 0.0, sp.yaw_rate)
        if self.state in ("pause", "acquire"):
            return HOVER
        if self.state == "search":
            assert self._square is not None
            wp = self._waypoint(self._last_t or 0.0, vehicle_ned) or self._square.waypoints[-1]
            vn, ve = clip_xy(
                c.kp_xy * (wp[0] - vehicle_ned[0]),
                c.kp_xy * (wp[1] - vehicle_ned[1]),
                self.search.speed,
            )
            vd = c.kp_z * (float(rel_ned[2]) - self._square.height)  # hold the search height
            return VelocitySetpoint(vn, ve, max(-c.max_climb, min(c.max_descent, vd)))
        if self.state == "fallback":  # down the RTK fixed GNSS to the surveyed pad
            return cone_setpoint(rel_ned, None, yaw, c)
        if self.state == "abort":  # up to the safe height over the surveyed pad, and hold there
            climb = self.search.abort_height_m - float(rel_ned[2])
            vd = -min(self.retry.climb_speed, max(c.kp_z * climb, 0.0))
            n, e = float(rel_ned[0]), float(rel_ned[1])
            vn, ve = clip_xy(c.kp_xy * n, c.kp_xy * e, self.search.speed)
            return VelocitySetpoint(vn, ve, vd)
        if self.state == "climb":
            assert self._goal is not None
            n, e, h = self._goal
            vn, ve = clip_xy(
                c.kp_xy * (n - vehicle_ned[0]), c.kp_xy * (e - vehicle_ned[1]), c.max_speed_xy
            )
            vd = -min(self.retry.climb_speed, c.kp_z * max(h - float(rel_ned[2]), 0.0) + 0.1)
            return VelocitySetpoint(vn, ve, vd)
        # blind: steer to the estimate and descend
        vn, ve = clip_xy(c.kp_xy * float(rel_ned[0]), c.kp_xy * float(rel_ned[1]), c.max_speed_xy)
        vd = self.retry.blind_descent
        if self._last_seen is not None:
            vd = blind_profile(float(rel_ned[2]) - c.touchdown_height, self.retry)
        a = float(rel_ned[2]) - c.touchdown_height
        if self.retry.blind_slow_final and a < c.slow_height:
            vd = min(vd, c.slow_descent)
        if self.waiting:  # outside the approach's cone, on a trusted estimate
            allowed = allowed_pos_error(a, c)
            vd = 0.0 if a < c.slow_height else min(vd, c.kp_z * min(allowed, a))
        return VelocitySetpoint(vn, ve, vd)

    def _blind_off_cone(self, now: float, rel_ned) -> bool:
        """Outside the approach's cone and within `blind_wait_height_m` of touchdown, a blind
        descent waits as the approach does (12 m/s, seed 1006: it went down regardless, 3.2 m
        off) — on an estimate worth waiting on: RTK fixed, or within `blind_recentre_s` of the
        last sighting (else waiting adds drift)."""
        seen, c = self._last_seen, self.control
        a = cone_position(rel_ned, c)[1]
        if seen is None or a > self.retry.blind_wait_height_m:
            return False
        recent = now - seen[3] <= self.retry.blind_recentre_s
        if not (recent or rtk_fixed(self._gnss_fix)):
            return False
        return not inside_cone(rel_ned, c) and (a >= c.slow_height or c.final_inside_cone_only)
