"""Pure multirotor point-mass dynamics: velocity tracking with limits, wind, battery, landing.

No I/O and no clock: the caller owns time and calls `step(dt, wind_ne)`. Coordinates are
local NED metres with the origin at the pad centre (z is down, the ground is z = 0).

Usage::

    dyn = Dynamics(DynamicsParams())
    dyn.motors_on = True
    dyn.set_position_target((10.0, 0.0, -5.0))   # fly to 10 m north, 5 m up
    for _ in range(200):
        dyn.step(0.05, wind_ne=(0.0, 0.0))
    dyn.state.position                           # true position (ground truth)

A position target is tracked with a sqrt (constant-deceleration) profile so the vehicle stops
on the target; a velocity target is tracked directly. Both are limited by the horizontal and
vertical speed limits and by the acceleration limit. Wind acts as a disturbance the
controller rejects once it has learnt it (`wind_adapt_s`); `wind_leak` is the fraction of the
not-yet-learnt wind (gusts, changes) that leaks into the ground velocity while flying.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

from sim.wind import overpowering

Vec3 = tuple[float, float, float]


class Phase(Enum):
    """What the vehicle is doing, for the battery model."""

    IDLE = "idle"  # motors off
    GROUND = "ground"  # armed, spinning on the ground
    HOVER = "hover"
    CRUISE = "cruise"
    CLIMB = "climb"


@dataclass(frozen=True)
class DynamicsParams:
    """Vehicle limits and the battery model."""

    max_speed_h: float = 12.0  # m/s
    max_speed_up: float = 2.5
    max_speed_down: float = 1.5
    max_accel: float = 3.0  # m/s^2, every axis
    pos_gain: float = 1.0  # 1/s, position error -> velocity
    yaw_rate: float = math.radians(90.0)  # rad/s
    attitude_tau_s: float = 0.15  # roll/pitch follow the demanded tilt with this time constant
    wind_leak: float = 0.1  # fraction of an unexpected wind change that shows in ground velocity
    wind_adapt_s: float = 1.0  # the controller learns a steady wind in about this long
    wind_authority_mps: float = 15.0  # wind it can lean into; the excess carries it (sim/wind.py)
    mass_g: float = 1450.0
    battery_capacity_mah: float = 5000.0
    cells: int = 4
    current_a: tuple[tuple[Phase, float], ...] = (
        (Phase.IDLE, 0.3),
        (Phase.GROUND, 2.0),
        (Phase.HOVER, 14.0),
        (Phase.CRUISE, 17.0),
        (Phase.CLIMB, 22.0),
    )
    landed_speed: float = 0.25  # below this vertical speed on the ground, landed


@dataclass(frozen=True)
class DynamicsState:
    """Ground truth of the vehicle at one instant."""

    position: Vec3 = (0.0, 0.0, 0.0)
    velocity: Vec3 = (0.0, 0.0, 0.0)
    yaw: float = 0.0  # rad, 0 = north
    roll: float = 0.0
    pitch: float = 0.0
    landed: bool = True
    battery_pct: float = 100.0
    current_a: float = 0.0
    consumed_mah: float = 0.0
    phase: Phase = Phase.IDLE

    @property
    def voltage(self) -> float:
        """Pack voltage for a 4S pack, from 14.0 V empty to 16.8 V full."""
        return 14.0 + 2.8 * self.battery_pct / 100.0

    @property
    def altitude(self) -> float:
        """Height above the ground in metres (positive up)."""
        return -self.position[2]


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def _approach(cur: float, want: float, max_delta: float) -> float:
    return cur + _clip(want - cur, -max_delta, max_delta)


def stopping_speed(distance: float, accel: float, gain: float, vmax: float) -> float:
    """Speed towards a target `distance` away that still stops on it (sqrt profile)."""
    return min(vmax, gain * distance, math.sqrt(2.0 * accel * max(distance, 0.0)))


class Dynamics:
    """One multirotor: set a target, call `step`, read `state` (ground truth)."""

    def __init__(
        self, params: DynamicsParams | None = None, state: DynamicsState | None = None
    ) -> None:
        self.params = params or DynamicsParams()
        self.state = state or DynamicsState()
        self.motors_on = False
        self._pos_target: Vec3 | None = None
        self._vel_target: Vec3 = (0.0, 0.0, 0.0)
        self._yaw_target: float | None = None
        self._limits: tuple[float | None, float | None, float | None] = (None, None, None)
        self._wind_est: tuple[float, float] = (0.0, 0.0)

    # --- targets ---------------------------------------------------------------------------
    def set_position_target(
        self,
        pos: Vec3,
        yaw: float | None = None,
        speed_h: float | None = None,
        speed_up: float | None = None,
        speed_down: float | None = None,
    ) -> None:
        """Fly to `pos` (NED metres) and stop there, optionally slower than the limits."""
        self._pos_target = pos
        self._limits = (speed_h, speed_up, speed_down)
        if yaw is not None:
            self._yaw_target = yaw

    def set_velocity_target(self, vel: Vec3, yaw: float | None = None) -> None:
        """Fly at `vel` (NED m/s) until told otherwise."""
        self._pos_target = None
        self._vel_target = vel
        self._limits = (None, None, None)
        if yaw is not None:
            self._yaw_target = yaw

    def hold(self) -> None:
        """Stop and hold the current position."""
        self.set_position_target(self.state.position)

    @property
    def position_target(self) -> Vec3 | None:
        """The current position target, or None in velocity control."""
        return self._pos_target

    def set_battery(self, pct: float) -> None:
        """Override the battery level (fault injection, scenarios)."""
        self.state = replace(self.state, battery_pct=_clip(pct, 0.0, 100.0))

    # --- integration -----------------------------------------------------------------------
    def _desired_velocity(self) -> Vec3:
        p = self.params
        s = self.state
        lim_h, lim_up, lim_down = self._limits
        vmax_h = min(p.max_speed_h, lim_h or p.max_speed_h)
        vmax_up = min(p.max_speed_up, lim_up or p.max_speed_up)
        vmax_down = min(p.max_speed_down, lim_down or p.max_speed_down)
        if self._pos_target is None:
            vn, ve, vd = self._vel_target
        else:
            dn = self._pos_target[0] - s.position[0]
            de = self._pos_target[1] - s.position[1]
            dd = self._pos_target[2] - s.position[2]
            dist_h = math.hypot(dn, de)
            speed_h = stopping_speed(dist_h, p.max_accel, p.pos_gain, vmax_h)
            vn = speed_h * dn / dist_h if dist_h > 1e-6 else 0.0
            ve = speed_h * de / dist_h if dist_h > 1e-6 else 0.0
            vmax_d = vmax_down if dd > 0 else vmax_up
            vd = math.copysign(stopping_speed(abs(dd), p.max_accel, p.pos_gain, vmax_d), dd)
        speed_h = math.hypot(vn, ve)
        if speed_h > vmax_h:
            vn, ve = vn * vmax_h / speed_h, ve * vmax_h / speed_h
        vd = _clip(vd, -vmax_up, vmax_down)
        return vn, ve, vd

    def step(self, dt: float, wind_ne: tuple[float, float] = (0.0, 0.0)) -> DynamicsState:
        """Advance `dt` seconds with the given wind; returns the new ground truth."""
        p, s = self.params, self.state
        if dt <= 0:
            return s
        if not self.motors_on:
            self.state = self._drain(replace(s, velocity=(0.0, 0.0, 0.0), roll=0.0, pitch=0.0), dt)
            return self.state
        want = self._desired_velocity()
        dv = p.max_accel * dt
        vn = _approach(s.velocity[0], want[0], dv)
        ve = _approach(s.velocity[1], want[1], dv)
        vd = _approach(s.velocity[2], want[2], dv)
        airborne = s.position[2] < -0.01 or vd < 0
        # the position controller's integrator learns the wind; only the unlearnt part (gusts,
        # changes) pushes the vehicle off its track
        k = min(1.0, dt / p.wind_adapt_s)
        self._wind_est = (
            self._wind_est[0] + (wind_ne[0] - self._wind_est[0]) * k,
            self._wind_est[1] + (wind_ne[1] - self._wind_est[1]) * k,
        )
        push = overpowering(wind_ne, p.wind_authority_mps) if airborne else (0.0, 0.0)
        leak_n = (wind_ne[0] - self._wind_est[0]) * p.wind_leak + push[0] if airborne else 0.0
        leak_e = (wind_ne[1] - self._wind_est[1]) * p.wind_leak + push[1] if airborne else 0.0
        n = s.position[0] + (vn + leak_n) * dt
        e = s.position[1] + (ve + leak_e) * dt
        d = s.position[2] + vd * dt
        landed = False
        if d >= 0.0:  # the ground
            d = 0.0
            vd = min(vd, 0.0)
            if want[2] >= 0.0:
                landed = True
                vn = ve = 0.0
                n, e = s.position[0], s.position[1]
        yaw = s.yaw
        if self._yaw_target is not None and not landed:
            err = (self._yaw_target - yaw + math.pi) % (2 * math.pi) - math.pi
            yaw = (yaw + _clip(err, -p.yaw_rate * dt, p.yaw_rate * dt)) % (2 * math.pi)
        # tilt from acceleration (small-angle), rotated into the body frame
        an, ae = (vn - s.velocity[0]) / dt, (ve - s.velocity[1]) / dt
        fwd = an * math.cos(yaw) + ae * math.sin(yaw)
        right = -an * math.sin(yaw) + ae * math.cos(yaw)
        lim = math.radians(35.0)
        pitch = _clip(-math.atan2(fwd, 9.81), -lim, lim) if not landed else 0.0
        roll = _clip(math.atan2(right, 9.81), -lim, lim) if not landed else 0.0
        if not landed and p.attitude_tau_s > 0:
            # the attitude loop follows the tilt the acceleration asks for with a time constant:
            # a real copter takes ~0.1-0.2 s to bank, never the 17 degrees in one 10 ms step that
            # a bang-bang acceleration would read as (a line of sight seen from 5 m swings metres)
            k = min(1.0, dt / p.attitude_tau_s)
            pitch = s.pitch + (pitch - s.pitch) * k
            roll = s.roll + (roll - s.roll) * k
        phase = Phase.GROUND if landed else self._phase(vn, ve, vd)
        new = replace(
            s,
            position=(n, e, d),
            velocity=(vn, ve, vd) if not landed else (0.0, 0.0, 0.0),
            yaw=yaw,
            roll=roll,
            pitch=pitch,
            landed=landed,
            phase=phase,
        )
        self.state = self._drain(new, dt)
        return self.state

    @staticmethod
    def _phase(vn: float, ve: float, vd: float) -> Phase:
        if vd < -0.5:
            return Phase.CLIMB
        if math.hypot(vn, ve) > 2.0:
            return Phase.CRUISE
        return Phase.HOVER

    def _drain(self, s: DynamicsState, dt: float) -> DynamicsState:
        phase = s.phase if self.motors_on else Phase.IDLE
        amps = dict(self.params.current_a)[phase]
        used = amps * dt / 3.6  # mAh
        pct = s.battery_pct - 100.0 * used / self.params.battery_capacity_mah
        return replace(
            s,
            phase=phase,
            current_a=amps,
            consumed_mah=s.consumed_mah + used,
            battery_pct=max(0.0, pct),
            landed=s.landed if self.motors_on else s.position[2] >= 0.0,
        )
