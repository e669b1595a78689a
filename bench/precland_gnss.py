"""The evaluation's GNSS error: what the autopilot's position carries, by fix type (seedable).

Each axis is a sum of first-order Gauss-Markov processes (sigma, time constant), the vertical
scaled by `vertical` (the height is baro-aided, as ArduPilot's EKF does by default). The
autopilot's EKF smooths the receiver's 5-10 Hz fixes, so what it reports drifts rather than jumps.

- `rtk_fixed` (the default: our bases send RTCM3 corrections, `sim/gnss`, and the UAV flies RTK):
  receiver noise 0.6 cm smoothed over 1 s, plus 0.6 cm of slow error (multipath, residual
  atmosphere) over 100 s — 0.85 cm per axis in all, the 1 cm CEP of a u-blox F9P-class receiver
  in RTK fixed; it drifts ~0.8 cm over the ~2.4 s of a blind final descent, the slow part
  0.85 mm/sqrt(s).
- `rtk_float` (corrections, ambiguities not fixed): 0.25 m over 60 s (4.6 cm/sqrt(s)).
- `3d` (no corrections): 0.5 m over 120 s (6.5 cm/sqrt(s) per axis).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.vehicle.gnss import FIX_NONE, FIX_RTK_FLOAT, GnssReading
from sim.vehicle.gnss import GnssModel as SimGnssModel

# GPS_RAW_INT fix_type
FIX_TYPES = {"3d": 3, "rtk_float": 5, "rtk_fixed": 6}


@dataclass(frozen=True)
class GnssModel:
    """Gauss-Markov components (sigma m, tau s) per axis and the vertical's scale."""

    fix: str
    components: tuple[tuple[float, float], ...]
    vertical: float = 0.5

    @property
    def fix_type(self) -> int:
        """The GPS_RAW_INT fix_type the autopilot reports with it."""
        return FIX_TYPES[self.fix]

    @property
    def sigma(self) -> float:
        """The stationary 1-sigma per horizontal axis (m)."""
        return math.sqrt(sum(s * s for s, _ in self.components))


MODELS = {
    "rtk_fixed": GnssModel("rtk_fixed", ((0.006, 1.0), (0.006, 100.0))),
    "rtk_float": GnssModel("rtk_float", ((0.25, 60.0),)),
    "3d": GnssModel("3d", ((0.5, 120.0),)),
}


class GnssError:
    """The error of the autopilot's position (NED, m) under one model, from its own generator."""

    def __init__(self, model: GnssModel, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self._scale = np.array([1.0, 1.0, model.vertical])
        self._parts = [rng.normal(0, s, 3) * self._scale for s, _ in model.components]

    @property
    def value(self) -> np.ndarray:
        """The current error."""
        return np.sum(self._parts, axis=0)

    def step(self, dt: float) -> np.ndarray:
        """Advance dt seconds; the current error."""
        for i, (sigma, tau) in enumerate(self.model.components):
            decay = math.exp(-dt / tau)
            drive = self.rng.normal(0, sigma * math.sqrt(1 - decay**2), 3) * self._scale
            self._parts[i] = self._parts[i] * decay + drive
        return self.value


class CopterGnss(SimGnssModel):
    """`GnssError` as the simulated autopilot's receiver (sim.vehicle.gnss.GnssModel's interface),
    so that the autopilot path's EKF position (`Copter.estimated_position`: truth plus this error)
    drifts as the agent path's GNSS does: the same model, the same draws for the same generator.
    The fix type is the model's while `has_fix`; `bias_ne_m` (fault injection) adds on top. The
    copter's estimated height stays its truth, as `Copter.estimated_position` keeps it."""

    def __init__(self, error: GnssError) -> None:
        super().__init__()
        self.error = error

    def fix_type(self, now: float) -> int:
        """The model's fix type (or no fix under fault injection)."""
        return self.error.model.fix_type if self.has_fix else FIX_NONE

    def step(self, dt: float, now: float) -> GnssReading:
        """Advance the error by `dt` seconds; the reading."""
        if dt > 0:
            self.error.step(dt)
        return self.reading(now)

    def reading(self, now: float) -> GnssReading:
        """The current reading without advancing the error."""
        fix = self.fix_type(now)
        e = self.error.value
        err = (float(e[0]) + self.bias_ne_m[0], float(e[1]) + self.bias_ne_m[1], float(e[2]))
        rtk = fix >= FIX_RTK_FLOAT
        sats = (
            0 if fix == FIX_NONE else self.params.satellites_rtk if rtk else self.params.satellites
        )
        hdop = 99.99 if fix == FIX_NONE else 0.6 if rtk else 0.9
        return GnssReading(fix, err, sats, hdop, self.error.model.sigma)
