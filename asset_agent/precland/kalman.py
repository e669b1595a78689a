"""Kalman filter of the pad's position relative to the vehicle (paper §2.5.2).

State: pad centre minus vehicle in NED (3), plus the pad's yaw as a separate angular state.
Predict with the autopilot's position *deltas* (so a wrong surveyed pad position, a constant
offset, never enters the motion model): rel ← rel − Δvehicle, with noise growing with distance
moved and time. Update with vision (or IR), the measurement noise growing with height (pixel
error). Until the first vision update the estimate is the GNSS one, with a large uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset_agent.precland.config import KalmanConfig
from asset_agent.precland.geometry import wrap_angle


@dataclass(frozen=True)
class Estimate:
    """The filter's estimate: relative position (NED, m), its 1-sigma, heading and its sigma."""

    rel_ned: tuple[float, float, float]
    sigma_m: float
    heading: float | None
    heading_sigma: float


class TargetKalman:
    """Linear KF on the relative position; a 1-D angular KF on the pad heading."""

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config or KalmanConfig()
        self.x = np.zeros(3)
        self.p = np.eye(3) * self.config.initial_sigma_m**2
        self.heading: float | None = None
        self.heading_var = self.config.initial_heading_sigma**2
        self.initialised = False
        self.updates = 0

    def reset(self, rel_ned, sigma_m: float | None = None, heading: float | None = None) -> None:
        """Start from a prior, e.g. the surveyed pad position minus the GNSS position."""
        s = self.config.initial_sigma_m if sigma_m is None else sigma_m
        self.x = np.asarray(rel_ned, dtype=np.float64).copy()
        self.p = np.eye(3) * s**2
        self.heading = heading
        self.heading_var = self.config.initial_heading_sigma**2
        self.initialised = True

    def predict(self, delta_vehicle_ned, dt: float) -> None:
        """The vehicle moved by `delta_vehicle_ned` (autopilot position delta) over `dt` seconds."""
        d = np.asarray(delta_vehicle_ned, dtype=np.float64)
        self.x = self.x - d
        q = self.config.process_per_metre * float(
            np.linalg.norm(d)
        ) + self.config.process_per_second * max(dt, 0.0)
        self.p = self.p + np.eye(3) * q**2
        self.heading_var += (self.config.heading_process_per_second * max(dt, 0.0)) ** 2

    def update(self, rel_ned, sigma_m: float | None = None, heading: float | None = None) -> None:
        """Fuse a measurement; sigma defaults to the vision model at the measured height."""
        z = np.asarray(rel_ned, dtype=np.float64)
        if sigma_m is None:
            sigma_m = max(
                self.config.vision_sigma_floor, self.config.vision_sigma_per_metre * abs(z[2])
            )
        if not self.initialised:
            self.reset(z, sigma_m)
        else:
            r = np.eye(3) * sigma_m**2
            k = self.p @ np.linalg.inv(self.p + r)
            self.x = self.x + k @ (z - self.x)
            self.p = (np.eye(3) - k) @ self.p
        if heading is not None:
            if self.heading is None:
                self.heading, self.heading_var = heading, self.config.heading_sigma**2
            else:
                r_h = self.config.heading_sigma**2
                gain = self.heading_var / (self.heading_var + r_h)
                self.heading = wrap_angle(self.heading + gain * wrap_angle(heading - self.heading))
                self.heading_var = (1 - gain) * self.heading_var
        self.updates += 1

    def estimate(self) -> Estimate:
        """The current estimate."""
        return Estimate(
            (float(self.x[0]), float(self.x[1]), float(self.x[2])),
            math.sqrt(float(np.trace(self.p)) / 3),
            self.heading,
            math.sqrt(self.heading_var),
        )
