"""Pure multirotor point-mass dynamics: thrust leaned against drag, limits, battery, landing.

No I/O and no clock: the caller owns time and calls `step(dt, wind_ne)` with the air's velocity
at the vehicle (sim/wind.py `Airflow` makes it from the weather). Coordinates are local NED
metres with the origin at the pad centre (z is down, the ground is z = 0).

Usage::

    dyn = Dynamics(DynamicsParams())
    dyn.motors_on = True
    dyn.set_position_target((10.0, 0.0, -5.0))   # fly to 10 m north, 5 m up
    for _ in range(200):
        dyn.step(0.05, wind_ne=(0.0, 0.0))
    dyn.state.position                           # true position (ground truth)

A position target is tracked with a sqrt (constant-deceleration) profile so the vehicle stops
on the target; a velocity target is tracked directly; both shaped by the speed limits and the
acceleration limit into the velocity the controller asks for. Horizontally the vehicle is a
mass pushed by its thrust, leaned at most `angle_max_deg` (ANGLE_MAX) and following the demanded
lean with `attitude_tau_s`, and dragged by the air it moves through (linear rotor drag plus
quadratic body drag, sized so that at ANGLE_MAX it holds `max_airspeed_mps`). The controller
leans into the drag it expects from its wind estimate (learnt in about `wind_adapt_s`, as the
velocity loop's integrator does) and corrects the velocity error with `vel_p` (PSC_VELXY_P).
So a steady wind is held at the lean it needs (22 degrees at 12 m/s), a gust it has not learnt
pushes it off until the loop catches up, and a wind stronger than the lean limit can hold
carries it downwind. Roll and pitch are that lean in the body frame. Vertically the vehicle
follows its vertical speed target within the acceleration limit (no vertical wind).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

Vec3 = tuple[float, float, float]
G = 9.81


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
    angle_max_deg: float = 30.0  # ANGLE_MAX: the most it leans, whatever the controller asks
    max_airspeed_mps: float = 15.0  # the airspeed its drag balances at ANGLE_MAX
    rotor_drag_per_s: float = 0.2  # linear drag per m/s of airspeed (rotors); the rest quadratic
    vel_p: float = 2.0  # PSC_VELXY_P: demanded acceleration per m/s of velocity error
    wind_adapt_s: float = 1.0  # the controller learns a steady wind in about this long
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
        self._command: tuple[float, float] = (0.0, 0.0)  # shaped horizontal velocity (NE)
        self._thrust: tuple[float, float] = (0.0, 0.0)  # horizontal thrust per mass (NE, m/s²)
        top = G * math.tan(math.radians(self.params.angle_max_deg))
        vmax, k1 = self.params.max_airspeed_mps, self.params.rotor_drag_per_s
        self._k2 = max(0.0, (top - k1 * vmax) / vmax**2)

    def drag(self, air_n: float, air_e: float) -> tuple[float, float]:
        """The drag's acceleration (NE, m/s²) on the vehicle moving at (air_n, air_e) m/s
        through the air: linear rotor drag plus quadratic body drag, against the motion."""
        k = self.params.rotor_drag_per_s + self._k2 * math.hypot(air_n, air_e)
        return -k * air_n, -k * air_e

    def hold_lean_deg(self, wind_mps: float) -> float:
        """The lean (degrees) it needs to hold station in a steady wind of `wind_mps`; above
        ANGLE_MAX it cannot."""
        return math.degrees(math.atan2(self.drag(-wind_mps, 0.0)[0], G))

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
        vd = _approach(s.velocity[2], want[2], dv)
        airborne = s.position[2] < -0.01 or vd < 0
        # the velocity the controller asks for, shaped by the acceleration limit, and the
        # acceleration that shaping asks for (the feedforward)
        cn = _approach(self._command[0], want[0], dv)
        ce = _approach(self._command[1], want[1], dv)
        ff = ((cn - self._command[0]) / dt, (ce - self._command[1]) / dt)
        self._command = (cn, ce)
        # the velocity loop's integrator learns the wind in about wind_adapt_s
        k = min(1.0, dt / p.wind_adapt_s)
        self._wind_est = (
            self._wind_est[0] + (wind_ne[0] - self._wind_est[0]) * k,
            self._wind_est[1] + (wind_ne[1] - self._wind_est[1]) * k,
        )
        vn, ve = s.velocity[0], s.velocity[1]
        if airborne:
            # lean to accelerate as shaped, against the drag expected from the wind estimate,
            # and to correct the velocity error; never beyond ANGLE_MAX
            expect = self.drag(cn - self._wind_est[0], ce - self._wind_est[1])
            an = ff[0] - expect[0] + p.vel_p * (cn - vn)
            ae = ff[1] - expect[1] + p.vel_p * (ce - ve)
            lean = math.hypot(an, ae)
            top = G * math.tan(math.radians(p.angle_max_deg))
            if lean > top:
                an, ae = an * top / lean, ae * top / lean
            # the attitude loop follows the demanded lean with a time constant (a real copter
            # takes ~0.1-0.2 s to bank; a line of sight seen from 5 m swings metres with it)
            k = min(1.0, dt / p.attitude_tau_s) if p.attitude_tau_s > 0 else 1.0
            tn, te = self._thrust
            self._thrust = (tn + (an - tn) * k, te + (ae - te) * k)
            drag = self.drag(vn - wind_ne[0], ve - wind_ne[1])
            vn += (self._thrust[0] + drag[0]) * dt
            ve += (self._thrust[1] + drag[1]) * dt
        else:  # standing on the ground: it does not slide
            vn = ve = 0.0
            self._thrust = (0.0, 0.0)
            self._command = (0.0, 0.0)
        n = s.position[0] + vn * dt
        e = s.position[1] + ve * dt
        d = s.position[2] + vd * dt
        landed = False
        if d >= 0.0:  # the ground
            d = 0.0
            vd = min(vd, 0.0)
            if want[2] >= 0.0:
                landed = True
                vn = ve = 0.0
                n, e = s.position[0], s.position[1]
                self._thrust = self._command = (0.0, 0.0)
        yaw = s.yaw
        if self._yaw_target is not None and not landed:
            err = (self._yaw_target - yaw + math.pi) % (2 * math.pi) - math.pi
            yaw = (yaw + _clip(err, -p.yaw_rate * dt, p.yaw_rate * dt)) % (2 * math.pi)
        # the lean in the body frame (the thrust's horizontal part over g)
        tn, te = self._thrust
        fwd = tn * math.cos(yaw) + te * math.sin(yaw)
        right = -tn * math.sin(yaw) + te * math.cos(yaw)
        pitch = -math.atan2(fwd, G) if not landed else 0.0
        roll = math.atan2(right, G) if not landed else 0.0
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
