"""Simulated base power: lead-acid bank, solar MPPT output over the day, grid, source choice.

Smart-charger rule (which source feeds the base's loads, reported as POWER_SOURCE):

1. SOLAR   when the MPPT output covers the whole load (the surplus charges the bank);
2. GRID    otherwise, when the grid is present (the grid also tops the bank up);
3. BATTERY otherwise (solar output, if any, still offsets part of the load).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum


class PowerSource(IntEnum):
    """POWER_SOURCE register values."""

    GRID = 0
    SOLAR = 1
    BATTERY = 2


@dataclass(frozen=True)
class PowerParams:
    """Sizing of the base's power system."""

    bank_capacity_wh: float = 1200.0  # 12 V, 100 Ah
    bank_initial_soc: float = 0.85
    solar_peak_w: float = 300.0
    idle_load_w: float = 25.0
    grid_charge_w: float = 150.0
    start_hour: float = 12.0


def solar_output_w(hour: float, peak_w: float, cloud_factor: float = 1.0) -> float:
    """MPPT output at local solar `hour` (sunrise 06:00, sunset 18:00), scaled by clouds."""
    h = hour % 24.0
    if h <= 6.0 or h >= 18.0:
        return 0.0
    return peak_w * math.sin(math.pi * (h - 6.0) / 12.0) * cloud_factor


def pick_source(solar_w: float, load_w: float, grid_present: bool) -> PowerSource:
    """The smart-charger rule of the module docstring."""
    if solar_w >= load_w:
        return PowerSource.SOLAR
    if grid_present:
        return PowerSource.GRID
    return PowerSource.BATTERY


def bank_voltage(soc: float, current_w: float = 0.0) -> float:
    """Terminal voltage of a 12 V lead-acid bank at `soc`, sagging a little under load."""
    return 11.8 + 1.0 * min(1.0, max(0.0, soc)) - 0.0005 * current_w


class PowerSystem:
    """The base's bank, solar panel and grid connection; step it with simulated seconds."""

    def __init__(self, params: PowerParams | None = None) -> None:
        self.params = params or PowerParams()
        self.soc = self.params.bank_initial_soc
        self.grid_present = True
        self.solar_w = 0.0
        self.load_w = self.params.idle_load_w
        self.source = PowerSource.GRID
        self.t = 0.0

    def step(self, dt: float, extra_load_w: float, raining: bool) -> None:
        """Advance `dt` simulated seconds with `extra_load_w` drawn by motors and charger."""
        p = self.params
        self.t += dt
        hour = p.start_hour + self.t / 3600.0
        self.solar_w = solar_output_w(hour, p.solar_peak_w, 0.25 if raining else 1.0)
        self.load_w = p.idle_load_w + extra_load_w
        self.source = pick_source(self.solar_w, self.load_w, self.grid_present)
        if self.source is PowerSource.SOLAR:
            net_w = self.solar_w - self.load_w
        elif self.source is PowerSource.GRID:
            net_w = p.grid_charge_w if self.soc < 1.0 else 0.0
        else:
            net_w = self.solar_w - self.load_w
        self.soc = min(1.0, max(0.0, self.soc + net_w * dt / 3600.0 / p.bank_capacity_wh))

    @property
    def voltage(self) -> float:
        """Bank terminal voltage."""
        draw = self.load_w if self.source is PowerSource.BATTERY else 0.0
        return bank_voltage(self.soc, draw)
