"""Kalman filter of the pad's position relative to the vehicle (paper §2.5.2).

State: pad centre minus vehicle in NED (3) and the bias of the horizontal autopilot velocity it
may be predicted with (2, a Gauss-Markov process), plus the pad's yaw as a separate angular state.
Predict with the vehicle's displacement — the autopilot's position *deltas*, or horizontally its
velocity integrated (so a wrong surveyed pad position, a constant offset, never enters the motion
model): rel ← rel − Δvehicle, with noise growing with distance moved and time — a random walk
whose variance per second and per metre is configured, so the filter behaves the same whatever
the rate it is predicted at. The GNSS part of that walk follows the fix type the autopilot
reports: an RTK fixed position drifts millimetres a second, a float or plain one centimetres, and
it is the drift that a blind descent flies on. Update with vision (or IR): the reading's own
sigma where the detector reports one, else growing with height (pixel error), inflated when
readings come faster than their errors decorrelate (so the camera's frame rate does not change
how much the filter trusts it). Until the first vision update the estimate is the GNSS one, with
a large uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset_agent.precland.config import KalmanConfig
from asset_agent.precland.geometry import wrap_angle

# GPS_RAW_INT fix_type (MAVLink GPS_FIX_TYPE)
FIX_3D, FIX_DGPS, FIX_RTK_FLOAT, FIX_RTK_FIXED = 3, 4, 5, 6


def rtk_fixed(fix_type: int | None) -> bool:
    """The autopilot reports an RTK fixed fix (None: unknown, so not)."""
    return fix_type is not None and fix_type >= FIX_RTK_FIXED


def gnss_drift(config: KalmanConfig, fix_type: int | None) -> float:
    """The GNSS position drift (m per sqrt(s)) the filter assumes for a fix type (None: unknown)."""
    if fix_type is None:
        return config.position_noise_m_per_sqrt_s
    if fix_type >= FIX_RTK_FIXED:
        return config.gnss_drift_rtk_fixed_m_per_sqrt_s
    if fix_type == FIX_RTK_FLOAT:
        return config.gnss_drift_rtk_float_m_per_sqrt_s
    return config.gnss_drift_3d_m_per_sqrt_s


@dataclass(frozen=True)
class Estimate:
    """The filter's estimate: relative position (NED, m), its 1-sigma, heading and its sigma."""

    rel_ned: tuple[float, float, float]
    sigma_m: float
    heading: float | None
    heading_sigma: float


class TargetKalman:
    """Linear KF on the relative position (and, predicting by velocity, the velocity's slow
    bias: while vision is there the filter learns it, so it does not drift the estimate once
    vision is gone); a 1-D angular KF on the pad heading."""

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config or KalmanConfig()
        self.updates = 0
        self._last_update_t: float | None = None
        self._start(np.zeros(3), None, None)
        self.initialised = False  # no prior yet: the first measurement will be one

    @property
    def x(self) -> np.ndarray:
        """The relative position (pad minus vehicle, NED)."""
        return self._x[:3]

    @property
    def velocity_bias(self) -> np.ndarray:
        """The estimated bias of the horizontal velocities predicted with (north, east, m/s)."""
        return self._x[3:]

    def reset(self, rel_ned, sigma_m: float | None = None, heading: float | None = None) -> None:
        """Start from a prior, e.g. the surveyed pad position minus the GNSS position."""
        self._start(rel_ned, sigma_m, heading)
        self.initialised = True

    def _start(self, rel_ned, sigma_m: float | None, heading: float | None) -> None:
        c = self.config
        s = c.initial_sigma_m if sigma_m is None else sigma_m
        self._x = np.concatenate([np.asarray(rel_ned, dtype=np.float64), np.zeros(2)])
        self.p = np.diag([s**2] * 3 + [c.velocity_bias_sigma**2] * 2)
        self.heading = heading
        self.heading_var = c.initial_heading_sigma**2

    def predict(
        self,
        delta_vehicle_ned,
        dt: float,
        by_velocity: bool = False,
        fix_type: int | None = None,
    ) -> None:
        """The vehicle moved by `delta_vehicle_ned` over `dt` seconds: an autopilot position
        delta (its GNSS drifting as `fix_type` says), or (`by_velocity`) horizontally its
        velocity integrated over dt, less the estimated bias."""
        c = self.config
        d = np.asarray(delta_vehicle_ned, dtype=np.float64)
        dt = max(dt, 0.0)
        f = np.eye(5)
        q = np.zeros(5)
        # random walks: the variance adds up per second and per metre, whatever the rate
        moved = float(np.linalg.norm(d))
        q[:3] = gnss_drift(c, fix_type) ** 2 * dt + c.position_noise_m_per_sqrt_m**2 * moved
        if by_velocity:  # the integrated velocity's random walk, plus the slow bias
            q[:2] = c.velocity_noise_m_per_sqrt_s**2 * dt
            if c.velocity_bias_tau_s > 0:
                f[:2, 3:] = np.eye(2) * dt  # rel += bias x dt
                phi = math.exp(-dt / c.velocity_bias_tau_s)
                f[3:, 3:] = np.eye(2) * phi
                q[3:] = c.velocity_bias_sigma**2 * (1 - phi**2)
        self._x = f @ self._x
        self._x[:3] -= d
        self.p = f @ self.p @ f.T + np.diag(q)
        self.heading_var += c.heading_noise_rad_per_sqrt_s**2 * dt

    def update(
        self,
        rel_ned,
        sigma_m: float | None = None,
        heading: float | None = None,
        t: float | None = None,
    ) -> None:
        """Fuse a measurement taken at time `t`; sigma (per reading) defaults to the vision model
        at the measured height, and is never below its floor. Given t, readings closer together
        than the configured error correlation time are trusted less, in proportion: n frames in
        that time count as one."""
        z = np.asarray(rel_ned, dtype=np.float64)
        c = self.config
        sigma_m = (
            c.vision_sigma(float(z[2])) if sigma_m is None else max(c.vision_sigma_floor, sigma_m)
        )
        inflate = self._correlation_inflation(t)
        if not self.initialised:
            self.reset(z, sigma_m)
        else:
            r = np.eye(3) * sigma_m**2 * inflate
            k = self.p[:, :3] @ np.linalg.inv(self.p[:3, :3] + r)  # H = [I 0]
            self._x = self._x + k @ (z - self._x[:3])
            p = self.p - k @ self.p[:3, :]
            self.p = (p + p.T) / 2
        if heading is not None:
            if self.heading is None:
                self.heading, self.heading_var = heading, self.config.heading_sigma**2
            else:
                r_h = self.config.heading_sigma**2 * inflate
                gain = self.heading_var / (self.heading_var + r_h)
                self.heading = wrap_angle(self.heading + gain * wrap_angle(heading - self.heading))
                self.heading_var = (1 - gain) * self.heading_var
        self.updates += 1

    def _correlation_inflation(self, t: float | None) -> float:
        """correlation time / interval since the previous reading, at least 1."""
        tau = self.config.vision_error_correlation_s
        last, self._last_update_t = self._last_update_t, t
        if t is None or last is None or tau <= 0:
            return 1.0
        return max(1.0, tau / max(t - last, 1e-6))

    def estimate(self) -> Estimate:
        """The current estimate."""
        return Estimate(
            (float(self.x[0]), float(self.x[1]), float(self.x[2])),
            math.sqrt(float(np.trace(self.p[:3, :3])) / 3),
            self.heading,
            math.sqrt(self.heading_var),
        )
