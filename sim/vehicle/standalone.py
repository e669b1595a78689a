"""A minimal always-open pad: the stand-in for the landing base until the world wires the real one."""

from __future__ import annotations

from dataclasses import dataclass, field

# a field near Porto, where the ALPHA base was flown
DEFAULT_PAD = (41.1780, -8.5960, 120.0)


@dataclass
class OpenPad:
    """Implements the vehicle's `Base` protocol: always lets the vehicle leave, records the load."""

    pad_geodetic: tuple[float, float, float] = DEFAULT_PAD
    open: bool = True
    mass_g: float = 0.0
    contacts_seated: bool = False
    history: list[tuple[float, bool]] = field(default_factory=list)

    def can_vehicle_leave(self) -> bool:
        """True while `open` (always, unless a test closes it)."""
        return self.open

    def set_pad_load(self, mass_g: float, contacts_seated: bool) -> None:
        """Record what the vehicle puts on the pad."""
        self.mass_g = mass_g
        self.contacts_seated = contacts_seated
        self.history.append((mass_g, contacts_seated))
