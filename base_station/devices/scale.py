"""Landing confirmation from the scale: the UAV's mass within its window and stable long enough."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class LandingStatus:
    """What the scale says about the UAV at one instant."""

    mass_g: float
    present: bool
    stable_for_s: float
    confirmed: bool


class LandingDetector:
    """Confirms a landing when the net mass stays in [min, max] and within a tolerance band
    for `stable_s` seconds; the confirmation holds while that remains true."""

    def __init__(
        self,
        min_mass_g: float,
        max_mass_g: float,
        stable_s: float,
        tolerance_g: float,
        tare_g: float = 0.0,
    ) -> None:
        self.min_mass_g, self.max_mass_g = min_mass_g, max_mass_g
        self.stable_s, self.tolerance_g, self.tare_g = stable_s, tolerance_g, tare_g
        self._since: float | None = None
        self._samples: deque[tuple[float, float]] = deque()
        self.confirmed = False

    def in_window(self, mass_g: float) -> bool:
        """Whether a net mass fits the UAV's window."""
        return self.min_mass_g <= mass_g <= self.max_mass_g

    def update(self, t: float, scale_mass_g: float) -> tuple[LandingStatus, bool]:
        """Feed one reading at time `t`; returns the status and whether it just got confirmed."""
        mass = scale_mass_g - self.tare_g
        if not self.in_window(mass):
            self._since, self.confirmed = None, False
            self._samples.clear()
            return LandingStatus(mass, False, 0.0, False), False
        self._samples.append((t, mass))
        while self._samples and self._samples[0][0] < t - self.stable_s:
            self._samples.popleft()
        values = [m for _, m in self._samples]
        if self._since is None or max(values) - min(values) > self.tolerance_g:
            self._since = t
            self._samples = deque([(t, mass)])
            self.confirmed = False
        stable_for = t - self._since
        was = self.confirmed
        self.confirmed = stable_for >= self.stable_s
        return LandingStatus(mass, True, stable_for, self.confirmed), self.confirmed and not was
