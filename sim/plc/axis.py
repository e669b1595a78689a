"""One motorised axis of the base (side panels or lift): travel, limit switches, stall."""

from __future__ import annotations

from dataclasses import dataclass

STALL_FACTOR = 1.5


@dataclass
class Axis:
    """A motor moving a load between a low limit (0.0) and a high limit (1.0) over `travel_s`.

    `jammed` models a mechanical stall: the motor is energised but the load does not move;
    the PLC's stall detection stops it once `travel_s * 1.5` has passed without a limit.
    """

    name: str
    travel_s: float
    run_current_ma: int
    position: float = 0.0
    direction: int = 0
    elapsed: float = 0.0
    jammed: bool = False

    @property
    def moving(self) -> bool:
        """Whether the motor is energised."""
        return self.direction != 0

    @property
    def at_high(self) -> bool:
        """High limit switch (panels fully open / lift fully up)."""
        return self.position >= 1.0

    @property
    def at_low(self) -> bool:
        """Low limit switch (panels fully closed / lift fully down)."""
        return self.position <= 0.0

    @property
    def current_ma(self) -> int:
        """Motor current: run current while moving, higher when jammed, else zero."""
        if not self.moving:
            return 0
        return int(self.run_current_ma * (2.5 if self.jammed else 1.0))

    def start(self, direction: int) -> None:
        """Drive towards the high (+1) or low (-1) limit; no-op when already there."""
        if (direction > 0 and self.at_high) or (direction < 0 and self.at_low):
            self.direction = 0
            return
        if direction != self.direction:
            self.elapsed = 0.0
        self.direction = 1 if direction > 0 else -1

    def stop(self) -> None:
        """De-energise the motor."""
        self.direction = 0
        self.elapsed = 0.0

    def step(self, dt: float) -> bool:
        """Advance `dt` simulated seconds; True when the stall timeout just tripped."""
        if not self.moving:
            return False
        self.elapsed += dt
        if not self.jammed:
            self.position = min(1.0, max(0.0, self.position + self.direction * dt / self.travel_s))
            if (self.direction > 0 and self.at_high) or (self.direction < 0 and self.at_low):
                self.stop()
                return False
        if self.elapsed > self.travel_s * STALL_FACTOR:
            self.stop()
            return True
        return False
