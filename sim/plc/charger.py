"""The base's UAV charger: CC/CV charging of a LiPo pack through the pad contacts."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum


class ChargerState(IntEnum):
    """CHARGER_STATE register values."""

    IDLE = 0
    CHARGING = 1
    COMPLETE = 2
    FAULT = 3


@dataclass(frozen=True)
class PackParams:
    """The UAV's battery pack and the charger's limits."""

    cells: int = 6
    capacity_mah: float = 5000.0
    internal_ohm: float = 0.05
    charger_max_ma: int = 10000
    cutoff_ma: int = 250
    recharge_below: float = 0.95


class Charger:
    """Constant current up to 4.2 V/cell, then constant voltage until the current tapers off."""

    def __init__(self, params: PackParams | None = None) -> None:
        self.params = params or PackParams()
        self.uav_soc: float | None = None
        self.state = ChargerState.IDLE
        self.current_ma = 0.0
        self.voltage_v = 0.0
        self.fault = False

    def ocv(self, soc: float) -> float:
        """Open-circuit voltage of the pack at `soc` (3.5 V/cell empty, 4.2 V/cell full)."""
        return self.params.cells * (3.5 + 0.7 * soc)

    def step(self, dt: float, enabled: bool, connected: bool, limit_ma: int) -> None:
        """Advance `dt` simulated seconds; `connected` = lift down and contacts seated."""
        p = self.params
        self.current_ma = 0.0
        self.voltage_v = self.ocv(self.uav_soc) if connected and self.uav_soc is not None else 0.0
        if self.fault:
            self.state = ChargerState.FAULT
            return
        if not (enabled and connected and self.uav_soc is not None):
            self.state = ChargerState.IDLE
            return
        if self.state == ChargerState.COMPLETE and self.uav_soc >= p.recharge_below:
            return
        limit = p.charger_max_ma if limit_ma <= 0 else min(limit_ma, p.charger_max_ma)
        v_max = p.cells * 4.2
        ocv = self.ocv(self.uav_soc)
        current_a = limit / 1000.0
        voltage = ocv + current_a * p.internal_ohm
        cv = voltage >= v_max
        if cv:
            current_a = max(0.0, (v_max - ocv) / p.internal_ohm)
            voltage = v_max
        if cv and current_a * 1000.0 < p.cutoff_ma:
            self.state = ChargerState.COMPLETE
            self.voltage_v = ocv
            return
        self.state = ChargerState.CHARGING
        self.current_ma = current_a * 1000.0
        self.voltage_v = voltage
        self.uav_soc = min(1.0, self.uav_soc + current_a * dt / (p.capacity_mah / 1000.0 * 3600.0))
