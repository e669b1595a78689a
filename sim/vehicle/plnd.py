"""ArduPilot's precision landing (PLND_ENABLED=1, PLND_TYPE=1, companion computer) as the simulated
autopilot's habit `plnd="ardupilot"`; no I/O, no clock: the copter calls `handle` for each
LANDING_TARGET and `update` on every simulation step, and asks `descent` what LAND should fly.

Modelled from ArduPilot's source (libraries/AC_PrecLand: AC_PrecLand.cpp, AC_PrecLand_MAVLink.cpp,
PosVelEKF.cpp, AC_PrecLand_StateMachine.cpp; ArduCopter/mode.cpp land_run_vertical_control,
land_run_horizontal_control, precland_run) and from what 4.7 SITL did when fed (the notes in
shared/notes/ardupilot-precision-landing.md); written here, not copied:

- a LANDING_TARGET gives a line of sight (frames BODY_FRD, or LOCAL_FRD rotated by yaw only;
  `position_valid` 1: (x, y, z) / distance, else the angles) and the `distance`; a measurement is
  usable for 1 s; without a `distance` the height comes from a rangefinder (`rangefinder`);
- it is taken `lag_s` late (PLND_LAG): rotated with the attitude of then, fused into a
  position/velocity Kalman filter per horizontal axis (PosVelEKF) predicted with the vehicle's
  velocity changes (process noise PLND_ACC_P_NSE · dt), measurement variance
  (z · (0.01 + 0.01·|gyro|) + 0.02)² (|gyro| from the attitude's change), innovations with NIS ≥ 3 rejected (at most 3 in a row);
  then predicted forward over the lag to now;
- "PrecLand: Target Found" on the first measurement, "Init Complete" after 2 s of measurements
  each < 0.5 s apart (else "Init Failed"); no fused measurement for 2 s: "Target Lost";
- LAND (and RTL's and a mission's final descent) steers to the target while it is acquired,
  holds the descent while farther than PLND_XY_DIST_MAX, and between 2 m and 0.35 m of measured
  range descends at LAND_SPEED/2 slowed by the horizontal error (0.1 m/s at 15 cm or more);
- the retry state machine (PLND_STRICT, PLND_RET_MAX, PLND_TIMEOUT, PLND_ALT_MIN/MAX): a target
  lost while in the sensor's range is descended on for PLND_TIMEOUT s, then retried (back to
  where the vehicle last saw it, 1.5 m higher), then the failsafe: hover (STRICT 2), hover 7 s
  then land (STRICT 1), land at once (STRICT 0). Without a rangefinder the range check fails
  whenever ALT_MIN or ALT_MAX is set, so, as on a vehicle with none, no retry ever starts.

Long because: AC_PrecLand's backend, estimator and retry state machine side by side, in the order
of ArduPilot's sources, so that each rule can be checked against them.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from sim.vehicle.precland import MAV_FRAME_LOCAL_FRD, TargetReading, _rotate

EKF_INIT_S = 2.0
EKF_INIT_SENSOR_MIN_UPDATE_S = 0.5
TARGET_TIMEOUT_S = 2.0
MEASUREMENT_VALID_S = 1.0
LOST_FOR_GOOD_S = 180.0
LOST_DIST_M = 30.0
RETRY_POS_ERROR_M = 0.75
RETRY_OFFSET_ALT_M = 1.5
FAILSAFE_HOLD_S = 7.0
SLOW_ACCEPTABLE_ERROR_M = 0.15
SLOW_MIN_DESCENT = 0.1


@dataclass(frozen=True)
class PlndParams:
    """The PLND_* parameters (ArduPilot's defaults) and the vehicle's rangefinder."""

    est_type: int = 1  # PLND_EST_TYPE: 0 raw sensor, 1 Kalman filter
    acc_p_nse: float = 2.5  # PLND_ACC_P_NSE
    lag_s: float = 0.02  # PLND_LAG (0.02-0.25)
    xy_dist_max: float = 2.5  # PLND_XY_DIST_MAX: no descent farther than this (0: always)
    has_xy_dist_max: bool = True  # the parameter exists (ArduPilot 4; 3.x always descended)
    strict: int = 1  # PLND_STRICT: 0 land vertically, 1 retry then land, 2 retry then hover
    ret_max: int = 4  # PLND_RET_MAX
    timeout_s: float = 4.0  # PLND_TIMEOUT: descend this long on a lost target before retrying
    alt_min: float = 0.75  # PLND_ALT_MIN (needs a rangefinder)
    alt_max: float = 8.0  # PLND_ALT_MAX (needs a rangefinder)
    fast_descend: bool = False  # PLND_OPTIONS bit 2: no slow final descent
    position_fields: bool = True  # reads x, y, z when position_valid (3.x read the angles only)
    rangefinder: bool = False  # a healthy downward rangefinder (the true height)


def _rate(
    before: tuple[float, float, float], after: tuple[float, float, float], dt: float
) -> float:
    """How fast the attitude turned (rad/s): the Euler angles' change, yaw wrapped."""
    if dt <= 0:
        return 0.0
    d = [a - b for a, b in zip(after, before, strict=True)]
    d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
    return math.sqrt(sum(x * x for x in d)) / dt


@dataclass(frozen=True)
class _Inertial:
    t: float
    dt: float
    attitude: tuple[float, float, float]
    dvel: tuple[float, float]  # the vehicle's NE velocity change over dt
    vel: tuple[float, float]


class _PosVel:
    """One axis of PosVelEKF: state (relative position, relative velocity), covariance P."""

    def __init__(self, pos: float, pos_var: float, vel: float, vel_var: float) -> None:
        self.x = [pos, vel]
        self.p = [pos_var, 0.0, vel_var]  # P00, P01, P11

    def predict(self, dt: float, dvel: float, dvel_noise: float) -> None:
        x, p = self.x, self.p
        self.x = [x[0] + dt * x[1], x[1] + dvel]
        self.p = [p[0] + 2 * dt * p[1] + dt * dt * p[2], p[1] + dt * p[2], p[2] + dvel_noise**2]

    def nis(self, z: float, r: float) -> float:
        return (z - self.x[0]) ** 2 / (self.p[0] + r)

    def fuse(self, z: float, r: float) -> None:
        x, p = self.x, self.p
        s = p[0] + r
        k0, k1 = p[0] / s, p[1] / s
        y = z - x[0]
        self.x = [x[0] + k0 * y, x[1] + k1 * y]
        self.p = [(1 - k0) * p[0], (1 - k0) * p[1], p[2] - k1 * p[1]]


@dataclass(frozen=True)
class Descent:
    """What LAND flies this step: a horizontal target (estimated NE) or None (hold where it is),
    the descent speed (m/s, 0 = hold height; None = LAND's own profile), or a retry position."""

    target_ne: tuple[float, float] | None
    descent: float | None
    retry_ned: tuple[float, float, float] | None = None


class ArduPrecLand:
    """AC_PrecLand with the MAVLink backend, its estimator and its retry state machine."""

    def __init__(self, params: PlndParams | None = None) -> None:
        self.p = params or PlndParams()
        self.texts: list[str] = []  # STATUSTEXTs to send
        self.accepted = 0
        self.rejected = 0
        self._history: deque[_Inertial] = deque()
        self._last_vel: tuple[float, float] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget everything (a new mode)."""
        self._meas: tuple[TargetReading, float] | None = None
        self._meas_used_t: float | None = None
        self._ekf: tuple[_PosVel, _PosVel] | None = None
        self._raw: list[float] = [0.0, 0.0]
        self._initialised = False
        self._acquired = False
        self._init_t = 0.0
        self._last_update_t = -math.inf
        self._outliers = 0
        self.rel_out: tuple[float, float] | None = None  # target minus vehicle, NE, now
        self.meas_z: float = 0.0  # the last measurement's down component
        self.state = "never_seen"  # found, recently_lost, never_seen, out_of_range
        self._last_valid_t = -math.inf
        self._last_seen_vehicle: tuple[float, float, float] | None = None
        self._wrong_frame_told = False
        self.was_acquired = False
        self.machine_reset()
        self.retries = 0

    def machine_reset(self) -> None:
        """AC_PrecLand_StateMachine::reset_failed_landing_statemachine."""
        self._lost_action = "init"
        self._retry_state = "init"
        self._failsafe_t: float | None = None

    def _say(self, text: str) -> None:
        self.texts.append(text)

    # --- the backend ------------------------------------------------------------------------
    def handle(self, r: TargetReading, now: float) -> str | None:
        """One LANDING_TARGET received at `now`; the reason when it is dropped."""
        if r.frame not in (12, MAV_FRAME_LOCAL_FRD):
            self.rejected += 1
            if not self._wrong_frame_told:
                self._wrong_frame_told = True
                return "Plnd: Frame not supported"
            return None
        if r.position_valid and self.p.position_fields and not r.distance > 0:
            self.rejected += 1
            return None
        self._meas = (r, now)
        self.accepted += 1
        return None

    def _los(self, r: TargetReading) -> tuple[float, float, float]:
        if r.position_valid and self.p.position_fields:
            return (r.x / r.distance, r.y / r.distance, r.z / r.distance)
        v = (-math.tan(r.angle_y), math.tan(r.angle_x), 1.0)
        n = math.sqrt(sum(c * c for c in v))
        return (v[0] / n, v[1] / n, v[2] / n)

    # --- every step ---------------------------------------------------------------------------
    def update(
        self,
        now: float,
        dt: float,
        attitude: tuple[float, float, float],
        vel_ne: tuple[float, float],
        pos_ned: tuple[float, float, float],
        height: float,
        gyro: float | None = None,
    ) -> None:
        """AC_PrecLand::update: record the inertial frame, run the estimator, judge the target.
        `gyro`: the body rate's magnitude (rad/s); by default from the attitude's change."""
        if gyro is None:
            gyro = _rate(self._history[-1].attitude, attitude, dt) if self._history else 0.0
        dvel = (0.0, 0.0) if self._last_vel is None else (
            vel_ne[0] - self._last_vel[0], vel_ne[1] - self._last_vel[1]
        )  # fmt: skip
        self._last_vel = vel_ne
        self._history.append(_Inertial(now, dt, attitude, dvel, vel_ne))
        while len(self._history) > 1 and now - self._history[1].t >= self.p.lag_s:
            self._history.popleft()
        self._run_estimator(now, height, gyro, pos_ned)
        self._check_target_status(now, height, pos_ned)

    def acquired(self, now: float) -> bool:
        """AC_PrecLand::target_acquired."""
        if now - self._last_update_t > TARGET_TIMEOUT_S:
            if self._acquired:
                self._say("PrecLand: Target Lost")
            self._initialised = False
            self._acquired = False
        return self._acquired

    def _run_estimator(self, now: float, height: float, gyro: float, pos: tuple) -> None:
        delayed = self._history[0]
        meas = self._measure(now, height, delayed, pos)
        if self.p.est_type == 0:
            if self.acquired(now):
                self._raw = [self._raw[0] - delayed.vel[0] * delayed.dt,
                             self._raw[1] - delayed.vel[1] * delayed.dt]  # fmt: skip
            if meas is not None:
                if not self._initialised:
                    self._say("PrecLand: Target Found")
                    self._initialised = True
                self._raw = [meas[0], meas[1]]
                self._last_update_t = now
                self._acquired = True
            if self.acquired(now):
                self._output()
            return
        if (self.acquired(now) or self._initialised) and self._ekf is not None:
            noise = self.p.acc_p_nse * delayed.dt
            self._ekf[0].predict(delayed.dt, -delayed.dvel[0], noise)
            self._ekf[1].predict(delayed.dt, -delayed.dvel[1], noise)
        if meas is not None:
            var = (meas[2] * (0.01 + 0.01 * gyro) + 0.02) ** 2
            if not self._initialised or self._ekf is None:
                self._say("PrecLand: Target Found")
                self._ekf = (
                    _PosVel(meas[0], var, -delayed.vel[0], 4.0),
                    _PosVel(meas[1], var, -delayed.vel[1], 4.0),
                )
                self._last_update_t = self._init_t = now
                self._initialised = True
            else:
                ex, ey = self._ekf
                if max(ex.nis(meas[0], var), ey.nis(meas[1], var)) < 3.0 or self._outliers >= 3:
                    self._outliers = 0
                    ex.fuse(meas[0], var)
                    ey.fuse(meas[1], var)
                    self._last_update_t = now
                else:
                    self._outliers += 1
        if not self.acquired(now) and self._initialised:  # check_ekf_init_timeout
            if now - self._last_update_t > EKF_INIT_SENSOR_MIN_UPDATE_S:
                self._initialised = False
                self._say("PrecLand: Init Failed")
            elif now - self._init_t > EKF_INIT_S:
                self._acquired = True
                self.was_acquired = True
                self._say("PrecLand: Init Complete")
        if self.acquired(now):
            self._output()

    def _measure(self, now: float, height: float, delayed: _Inertial, pos: tuple) -> tuple | None:
        """A new measurement, as (north, east, down) of the target from the vehicle, or None."""
        if self._meas is None:
            return None
        r, t = self._meas
        if now - t > MEASUREMENT_VALID_S or self._meas_used_t == t:
            return None
        self._meas_used_t = t
        los = self._los(r)
        if los[2] <= 0:  # not towards the ground below (PITCH_270 approach vector)
            return None
        roll, pitch, yaw = delayed.attitude
        if r.frame == MAV_FRAME_LOCAL_FRD:
            roll = pitch = 0.0
        ned = _rotate(los, roll, pitch, yaw)
        if r.distance > 0:
            dist = r.distance
        elif self.p.rangefinder and height > 0 and ned[2] > 0:
            dist = height / ned[2]
        else:
            return None
        self._last_seen_vehicle = pos
        self.meas_z = ned[2] * dist
        return ned[0] * dist, ned[1] * dist, ned[2] * dist

    def _output(self) -> None:
        """run_output_prediction: from the delayed horizon forward to now."""
        if self.p.est_type == 0 or self._ekf is None:
            pos, vel = list(self._raw), [-self._history[0].vel[0], -self._history[0].vel[1]]
        else:
            pos = [self._ekf[0].x[0], self._ekf[1].x[0]]
            vel = [self._ekf[0].x[1], self._ekf[1].x[1]]
        for f in list(self._history)[1:]:
            vel = [vel[0] - f.dvel[0], vel[1] - f.dvel[1]]
            pos = [pos[0] + vel[0] * f.dt, pos[1] + vel[1] * f.dt]
        self.rel_out = (pos[0], pos[1])

    def _check_target_status(self, now: float, height: float, pos: tuple) -> None:
        if self.acquired(now):
            self.state = "found"
            self._last_valid_t = now
            return
        seen = self.state in ("found", "recently_lost")
        self.state = "recently_lost" if seen else "never_seen"
        if not self._in_range(height):
            self.state = "out_of_range"
            return
        if self.state == "recently_lost" and self._last_seen_vehicle is not None:
            if (
                now - self._last_valid_t > LOST_FOR_GOOD_S
                or math.hypot(
                    pos[0] - self._last_seen_vehicle[0], pos[1] - self._last_seen_vehicle[1]
                )
                > LOST_DIST_M
            ):
                self.state = "never_seen"

    def _in_range(self, height: float) -> bool:
        p = self.p
        if p.alt_min == 0 and p.alt_max == 0:
            return True
        if not p.rangefinder:
            return False
        return not ((p.alt_max and height > p.alt_max) or (p.alt_min and height < p.alt_min))

    def target_ne(self, now: float, pos_ne: tuple[float, float]) -> tuple[float, float] | None:
        """Where the target is (estimated NE) while acquired (get_target_position_cm)."""
        if not self.acquired(now) or self.rel_out is None:
            return None
        return pos_ne[0] + self.rel_out[0], pos_ne[1] + self.rel_out[1]

    # --- LAND with precision landing (precland_run) --------------------------------------------
    def descent(
        self, now: float, pos_ned: tuple[float, float, float], land_speed: float
    ) -> Descent:
        """What LAND flies now: the state machine's verdict, then the land controllers."""
        status = self._machine(now, pos_ned)
        if isinstance(status, tuple):
            return Descent(None, 0.0, status)
        if status == "failsafe":
            if self._failsafe_t is None:
                self._failsafe_t = now
                self._say("PrecLand: Failsafe Measures")
            hold = self.p.strict == 2 or (
                self.p.strict == 1 and now - self._failsafe_t < FAILSAFE_HOLD_S
            )
            return Descent(None, 0.0 if hold else None)
        target = self.target_ne(now, (pos_ned[0], pos_ned[1]))
        if target is None:
            return Descent(None, None)
        error = math.hypot(target[0] - pos_ned[0], target[1] - pos_ned[1])
        if self.p.xy_dist_max and error > self.p.xy_dist_max:
            return Descent(target, 0.0)
        if 0.35 < self.meas_z < 2.0 and not self.p.fast_descend:
            top = land_speed * 0.5
            slow = max(0.0, error * top / SLOW_ACCEPTABLE_ERROR_M)
            return Descent(target, max(SLOW_MIN_DESCENT, top - slow))
        return Descent(target, None)

    def _machine(self, now: float, pos: tuple) -> str | tuple[float, float, float]:
        """AC_PrecLand_StateMachine::update: "descend", "failsafe" or a retry position."""
        if self.state == "never_seen":
            return "failsafe"
        if self.state in ("found", "out_of_range"):
            self.machine_reset()
            return "descend"
        if self._lost_action == "init":
            self._lost_action = "descend" if self.p.strict in (1, 2) else "vertical"
            return "descend"
        if self._lost_action == "vertical":
            return "descend"
        if self._lost_action == "descend":
            if now - self._last_valid_t >= self.p.timeout_s:
                self._lost_action, self._retry_state = "retry", "init"
            return "descend"
        return self._retry(pos)

    def _retry(self, pos: tuple) -> str | tuple[float, float, float]:
        if self.p.ret_max == 0 or self.retries > self.p.ret_max or self._last_seen_vehicle is None:
            return "failsafe"
        n, e, d = self._last_seen_vehicle
        goal = (n, e, d - RETRY_OFFSET_ALT_M)
        if self._retry_state == "init":
            self.retries += 1
            self._retry_state = "going"
            if self.retries <= self.p.ret_max:
                self._say("PrecLand: Retrying")
            return goal
        if self._retry_state == "going":
            if math.dist(goal, pos) < RETRY_POS_ERROR_M:
                self._retry_state = "descending"
            return goal
        if self._retry_state == "descending":
            back = (pos[0], pos[1], d)
            if abs(pos[2] - d) < RETRY_POS_ERROR_M:
                self._retry_state = "complete"
                self._say("PrecLand: Retry Completed")
            return back
        return "failsafe"
