"""Landing control as pure functions: LANDING_TARGET fields for the autopilot, and the companion
mode's velocity setpoints inside the paper's conical acceptance volume (§2.6, eq. 3 and 4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset_agent.precland.config import ControlConfig, RetryConfig
from asset_agent.precland.geometry import rotation_world_from_body, wrap_angle
from asset_agent.precland.kalman import rtk_fixed
from asset_agent.precland.measure import Attitude

MAV_FRAME_BODY_FRD = 12
LANDING_TARGET_TYPE_VISION_FIDUCIAL = 2


@dataclass(frozen=True)
class LandingTarget:
    """The fields of MAVLink LANDING_TARGET (#149), ready for `landing_target_send`.

    Angles per ArduPilot's companion backend: its line of sight is (-tan(angle_y), tan(angle_x), 1)
    in body FRD, so angle_x is towards the right and angle_y towards the tail. The position
    (x, y, z) is also filled, in MAV_FRAME_BODY_FRD, with position_valid = 1 and distance > 0.
    """

    time_usec: int
    target_num: int
    frame: int
    angle_x: float
    angle_y: float
    distance: float
    size_x: float
    size_y: float
    x: float
    y: float
    z: float
    q: tuple[float, float, float, float]
    type: int
    position_valid: int

    @property
    def below(self) -> bool:
        """The pad is below the camera, as ArduPilot requires (not level with it: touched down)."""
        return self.z > MIN_BELOW * self.distance


# ArduPilot refuses a line of sight that is not below the vehicle (body z over distance)
MIN_BELOW = 0.1


def landing_target(
    rel_ned, attitude: Attitude, t: float, target_size_m: float = 0.75
) -> LandingTarget:
    """LANDING_TARGET for a pad at `rel_ned` (pad minus vehicle, NED) seen at `attitude`."""
    body = rotation_world_from_body(*attitude).T @ np.asarray(rel_ned, dtype=np.float64)
    x, y, z = (float(v) for v in body)
    dist = float(np.linalg.norm(body))
    zc = max(z, 1e-3)
    return LandingTarget(
        time_usec=round(t * 1e6),
        target_num=0,
        frame=MAV_FRAME_BODY_FRD,
        angle_x=math.atan2(y, zc),
        angle_y=math.atan2(-x, zc),
        distance=dist,
        size_x=2 * math.atan2(target_size_m / 2, max(dist, 1e-3)),
        size_y=2 * math.atan2(target_size_m / 2, max(dist, 1e-3)),
        x=x,
        y=y,
        z=z,
        q=(1.0, 0.0, 0.0, 0.0),
        type=LANDING_TARGET_TYPE_VISION_FIDUCIAL,
        position_valid=1,
    )


def allowed_pos_error(a: float, cfg: ControlConfig) -> float:
    """AllowedPosError(a) = minPosError · e^(maxPosError · a) (paper eq. 3)."""
    return cfg.min_pos_error * math.exp(cfg.max_pos_error * max(a, 0.0))


def cone_position(rel_ned, cfg: ControlConfig) -> tuple[float, float]:
    """(horizontal distance to the pad, altitude above touchdown) of an estimate `rel_ned` (pad
    minus vehicle, NED; `rel_ned[2]` the camera's height above the pad): where it is in the cone."""
    n, e, height = (float(v) for v in rel_ned)
    return math.hypot(n, e), height - cfg.touchdown_height


def inside_cone(rel_ned, cfg: ControlConfig) -> bool:
    """The pad within the acceptance cone at the vehicle's height (eq. 3)."""
    off, a = cone_position(rel_ned, cfg)
    return off <= allowed_pos_error(a, cfg)


@dataclass(frozen=True)
class VelocitySetpoint:
    """A GUIDED velocity setpoint in local NED (m/s), a yaw rate (rad/s), and "land now"."""

    vn: float
    ve: float
    vd: float
    yaw_rate: float = 0.0
    land: bool = False


HOVER = VelocitySetpoint(0.0, 0.0, 0.0)


def clip_xy(vn: float, ve: float, limit: float) -> tuple[float, float]:
    """(vn, ve) scaled down to at most `limit` m/s horizontally."""
    speed = math.hypot(vn, ve)
    if speed > limit:
        return vn * limit / speed, ve * limit / speed
    return vn, ve


def heading_error(pad_heading: float | None, yaw: float, cfg: ControlConfig) -> float | None:
    """Desired minus current vehicle yaw (rad), or None when the pad's heading is unknown."""
    if pad_heading is None:
        return None
    return wrap_angle(pad_heading + math.radians(cfg.heading_offset_deg) - yaw)


def held_off_centre(n: float, e: float, a: float, cfg: ControlConfig) -> bool:
    """The final stretch is never finished off-centre (`final_inside_cone_only`): `a` metres
    above touchdown, outside the cone at that altitude, the descent waits."""
    return (
        cfg.final_inside_cone_only
        and a < cfg.slow_height
        and math.hypot(n, e) > allowed_pos_error(a, cfg)
    )


def cone_setpoint(
    rel_ned, pad_heading: float | None, yaw: float, cfg: ControlConfig
) -> VelocitySetpoint:
    """Velocity towards the pad: centre always; descend to the pad inside the cone, towards
    a − AllowedPosError(a) outside it (eq. 4); no descent while the heading error is too big;
    slow in the final 50 cm; land at touchdown. `rel_ned[2]` is the camera's height above the
    pad; the cone's altitude `a` is measured from touchdown."""
    n, e, height = (float(v) for v in rel_ned)
    a = height - cfg.touchdown_height  # altitude above touchdown: the cone's apex is the seat
    vn, ve = clip_xy(cfg.kp_xy * n, cfg.kp_xy * e, cfg.max_speed_xy)
    err = heading_error(pad_heading, yaw, cfg)
    yaw_rate = 0.0
    if err is not None:
        yaw_rate = max(-cfg.max_yaw_rate, min(cfg.max_yaw_rate, cfg.kp_yaw * err))
    off = held_off_centre(n, e, a, cfg)
    if a <= cfg.land_margin and not off:
        return VelocitySetpoint(0.0, 0.0, cfg.slow_descent, 0.0, land=True)
    allowed = allowed_pos_error(a, cfg)
    if err is not None and abs(err) > math.radians(cfg.max_heading_error_deg):
        vd = 0.0
    elif math.hypot(n, e) <= allowed:
        vd = max(cfg.kp_z * a, cfg.final_descent_floor)  # setpoint on the pad: altitude 0
    elif off:  # never finish the slow final stretch off-centre: wait to be inside the cone,
        vd = 0.0 if a >= cfg.back_off_height else -cfg.slow_descent  # backing off the seat
    else:
        vd = cfg.kp_z * min(allowed, a)  # setpoint a - AllowedPosError(a)
    vd = min(vd, cfg.max_descent)
    if a < cfg.slow_height:
        vd = min(vd, cfg.slow_descent)
    return VelocitySetpoint(vn, ve, vd, yaw_rate)


def blind_allowed(above_touchdown: float, gnss_fix: int | None, retry: RetryConfig) -> bool:
    """A blind descent to the seat from `above_touchdown` metres: on RTK fixed, or within
    `blind_max_height_unfixed_m` (None: from anywhere, the thesis's rule)."""
    limit = retry.blind_max_height_unfixed_m
    return limit is None or rtk_fixed(gnss_fix) or above_touchdown <= limit


def blind_profile(above_touchdown: float, retry: RetryConfig) -> float:
    """Blind descent speed after a target was seen: fast, slowing at `blind_flare_decel` so as to
    be down to `blind_descent` (a safe touchdown speed) `blind_flare_margin_m` above touchdown,
    the height error a few blind seconds may have grown."""
    v0 = retry.blind_descent
    above = max(above_touchdown - retry.blind_flare_margin_m, 0.0)
    return max(
        v0, min(retry.blind_fast_descent, math.sqrt(v0**2 + 2 * retry.blind_flare_decel * above))
    )
