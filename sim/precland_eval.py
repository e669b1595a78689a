"""`aerobase sim precland-eval`: closed-loop precision landings, in process, per scenario.

Each trial: render → detect → fault injection → fusion → Kalman → control → vehicle, stepped at
100 Hz of simulated time (camera 33 Hz, IR 50 Hz, control 33 Hz), as fast as the CPU allows.
The vehicle is `KinematicVehicle`, a small model of our own (the shared multirotor dynamics were
not committed when this was written): first-order velocity tracking with acceleration and speed
limits, attitude from the acceleration it demands plus the wind it leans into (max 15°), a
fraction of the wind and gusts leaking into ground speed, and a seat at camera height 0.25 m.
Start 10 m (or 6 m) high and 2 m off; the surveyed pad position carries a setup error of up to
1 m; GNSS without RTK adds a Gauss-Markov error (0.3 m, 30 s) to the positions the agent sees.
Prints a table (scenario, mean / max landing error in cm, heading error, mean landing time) and,
with --json, one JSON object last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from asset_agent.precland.control import VelocitySetpoint
from asset_agent.precland.geometry import wrap_angle

G = 9.81
SEAT_HEIGHT = 0.25  # camera height above the pad when the vehicle sits on it


@dataclass
class KinematicVehicle:
    """A multirotor as a velocity-tracking point mass with yaw, tilt from acceleration and wind."""

    n: float
    e: float
    up: float
    yaw: float
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))  # NED m/s
    roll: float = 0.0
    pitch: float = 0.0
    tau: float = 0.35
    max_accel: float = 3.0
    max_tilt: float = math.radians(15)
    wind_leak: float = 0.05
    landed: bool = False

    def pose(self) -> tuple[float, float, float, float, float, float]:
        """(north, east, up, roll, pitch, yaw) relative to the pad centre."""
        return (self.n, self.e, self.up, self.roll, self.pitch, self.yaw)

    def step(self, dt: float, sp: VelocitySetpoint, wind_ne=(0.0, 0.0)) -> None:
        """Advance dt seconds tracking the setpoint, pushed by the wind."""
        if self.landed:
            return
        target = np.array([sp.vn, sp.ve, sp.vd])
        if sp.land:
            target = np.array([0.0, 0.0, 0.3])
        acc = (target - self.vel) / max(self.tau, dt)
        norm = float(np.linalg.norm(acc[:2]))
        if norm > self.max_accel:
            acc[:2] *= self.max_accel / norm
        self.vel = self.vel + acc * dt
        self.yaw = wrap_angle(self.yaw + sp.yaw_rate * dt)
        wn, we = wind_ne
        self.n += (self.vel[0] + self.wind_leak * wn) * dt
        self.e += (self.vel[1] + self.wind_leak * we) * dt
        self.up -= self.vel[2] * dt
        # lean into the demanded acceleration and the wind (drag ~ 0.015 g per m/s of wind)
        an, ae = acc[0] + 0.15 * wn, acc[1] + 0.15 * we
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        fwd, right = c * an + s * ae, -s * an + c * ae
        self.pitch = max(-self.max_tilt, min(self.max_tilt, -math.atan2(fwd, G)))
        self.roll = max(-self.max_tilt, min(self.max_tilt, math.atan2(right, G)))
        if self.up <= SEAT_HEIGHT:
            self.up, self.landed = SEAT_HEIGHT, True
            self.vel = np.zeros(3)
            self.roll = self.pitch = 0.0
