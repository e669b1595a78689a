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
