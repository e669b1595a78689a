"""The simulated landing base as its PLC sees it: a pure, steppable model with a register image.

Physics (travel, charging, power, scale) advances with `step(dt_sim)` in SIMULATED seconds;
communication timing (heartbeat, watchdog) advances with `tick_wall(now)` in WALL seconds.
No I/O here: `sim/plc/server.py` serves `coils()`, `discrete_inputs()`,
`input_registers()`, `holding_registers()` over Modbus TCP and feeds writes back in.

Decisions the spec leaves open (documented in sim/README.md too):

- Command coils are processed the moment they are written (one PLC scan), so a master
  reading them back sees 0; refused commands set INTERLOCK_REFUSED, accepted ones clear it.
- The watchdog arms on the FIRST write of holding register 0 (not at power-up), so the base
  does not fault while no master has ever connected; once armed it stays armed.
- Latched faults that block motion: panel stall (1), lift stall (2), watchdog (16), E-stop (32).
  Charger fault (4) and weather-sensor fault (8) are live status bits: they do not block
  motion (a base must still be able to close when its anemometer dies).
- CHARGE_CURRENT_LIMIT 0 means "the charger's own maximum".
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from sim.plc.axis import Axis
from sim.plc.charger import Charger, ChargerState
from sim.power import PowerSystem
from sim.weather import Weather

# coils
PANELS_OPEN, PANELS_CLOSE, LIFT_UP, LIFT_DOWN, MOTION_STOP, CHARGER_ENABLE, FAULT_RESET = range(7)
COIL_NAMES = (
    "PANELS_OPEN",
    "PANELS_CLOSE",
    "LIFT_UP",
    "LIFT_DOWN",
    "MOTION_STOP",
    "CHARGER_ENABLE",
    "FAULT_RESET",
)
N_COILS, N_DISCRETE, N_INPUT, N_HOLDING = 7, 11, 20, 2

FAULT_PANEL_STALL, FAULT_LIFT_STALL, FAULT_CHARGER = 1, 2, 4
FAULT_WEATHER, FAULT_WATCHDOG, FAULT_ESTOP = 8, 16, 32
LATCHED_FAULTS = FAULT_PANEL_STALL | FAULT_LIFT_STALL | FAULT_WATCHDOG | FAULT_ESTOP

WATCHDOG_TIMEOUT_S = 2.0
HEARTBEAT_PERIOD_S = 0.1
UNKNOWN_SOC = 65535


@dataclass(frozen=True)
class CommandRecord:
    """One command coil the PLC processed (ground truth for tests)."""

    t_sim: float
    coil: str
    accepted: bool
    reason: str


@dataclass(frozen=True)
class BaseParams:
    """Physical constants of the simulated base."""

    panels_travel_s: float = 12.0
    lift_travel_s: float = 8.0
    scale_tare_g: float = 15.0
    scale_noise_g: float = 2.0
    default_charge_limit_ma: int = 5000
    pad_geodetic: tuple[float, float, float] = (41.1780, -8.5980, 120.0)


def _u16(value: float) -> int:
    return max(0, min(65535, round(value)))


class LandingBase:
    """The base: panels, lift, scale, charger, power and weather sensors behind one PLC."""

    def __init__(
        self,
        weather: Weather,
        power: PowerSystem | None = None,
        params: BaseParams | None = None,
        seed: int = 0,
    ) -> None:
        self.params = p = params or BaseParams()
        self.weather = weather
        self.power = power or PowerSystem()
        self.charger = Charger()
        self.panels = Axis("panels", p.panels_travel_s, 2500)
        self.lift = Axis("lift", p.lift_travel_s, 4000)
        self._rng = random.Random(seed + 1)
        self.t_sim = 0.0
        self.charger_enable = False
        self.watchdog_value = 0
        self.charge_limit_ma = p.default_charge_limit_ma
        self.faults = 0
        self.estop_active = False
        self.interlock_refused = False
        self.pad_mass_g = 0.0
        self.contacts_seated = False
        self.scale_g = p.scale_tare_g
        self.pad_geodetic: tuple[float, float, float] = p.pad_geodetic
        self.command_log: list[CommandRecord] = []
        self._wall_start: float | None = None
        self._wall_now = 0.0
        self._watchdog_changed_at: float | None = None
        self._heartbeat = 0
        self.cpu_halted = False

    # --- vehicle-facing API --------------------------------------------------------------

    def can_vehicle_leave(self) -> bool:
        """Panels fully open and lift fully up."""
        return self.panels.at_high and self.lift.at_high

    def set_pad_load(self, mass_g: float, contacts_seated: bool) -> None:
        """What stands on the pad: its mass and whether its charge contacts are seated."""
        self.pad_mass_g = max(0.0, float(mass_g))
        self.contacts_seated = bool(contacts_seated) and self.pad_mass_g > 0.0

    def set_uav_battery(self, soc: float | None) -> None:
        """State of charge (0..1) of the battery standing on the pad; None = no battery."""
        self.charger.uav_soc = None if soc is None else min(1.0, max(0.0, soc))

    # --- fault injection -----------------------------------------------------------------

    def inject_stall(self, axis: str, on: bool = True, immediate: bool = False) -> None:
        """Jam an axis (the PLC detects it by timeout) or, `immediate`, latch its stall now."""
        target = self._axis(axis)
        target.jammed = on
        if on and immediate:
            target.stop()
            self.faults |= FAULT_PANEL_STALL if target is self.panels else FAULT_LIFT_STALL

    def set_estop(self, on: bool) -> None:
        """Press (True) or release (False) the emergency stop."""
        self.estop_active = on
        if on:
            self._stop_all()
            self.faults |= FAULT_ESTOP

    def set_cpu_halt(self, on: bool) -> None:
        """Halt (True) or restart the PLC CPU: outputs drop, commands and heartbeat freeze."""
        self.cpu_halted = on
        if on:
            self._stop_all()

    def _axis(self, name: str) -> Axis:
        if name == "panels":
            return self.panels
        if name == "lift":
            return self.lift
        raise KeyError(f"unknown axis {name!r} (panels or lift)")

    # --- Modbus writes -------------------------------------------------------------------

    def write_coils(self, address: int, values: list[bool]) -> None:
        """A master wrote coils starting at `address`; command coils are processed at once."""
        for offset, value in enumerate(values):
            coil = address + offset
            if coil == CHARGER_ENABLE:
                self.charger_enable = bool(value)
            elif 0 <= coil < N_COILS and value and not self.cpu_halted:
                self._command(coil)

    def write_holding(self, address: int, values: list[int], wall_now: float) -> None:
        """A master wrote holding registers starting at `address` at wall time `wall_now`."""
        for offset, value in enumerate(values):
            reg = address + offset
            if reg == 0:
                if self._watchdog_changed_at is None or value != self.watchdog_value:
                    self._watchdog_changed_at = wall_now
                self.watchdog_value = value
            elif reg == 1:
                self.charge_limit_ma = value

    def _command(self, coil: int) -> None:
        if coil == MOTION_STOP:
            self._stop_all()
            self._record(coil, True, "")
            return
        if coil == FAULT_RESET:
            keep = FAULT_ESTOP if self.estop_active else 0
            self.faults &= ~(LATCHED_FAULTS & ~keep)
            self._record(coil, True, "")
            return
        reason = self._refusal(coil)
        if reason:
            self._record(coil, False, reason)
            return
        if coil == PANELS_OPEN:
            self.panels.start(+1)
        elif coil == PANELS_CLOSE:
            self.panels.start(-1)
        elif coil == LIFT_UP:
            self.lift.start(+1)
        elif coil == LIFT_DOWN:
            self.lift.start(-1)
        self._record(coil, True, "")

    def _refusal(self, coil: int) -> str:
        if self.estop_active:
            return "E-stop active"
        if self.faults & LATCHED_FAULTS:
            return f"faults latched ({self.faults & LATCHED_FAULTS})"
        if coil == LIFT_UP and not (self.panels.at_high and not self.panels.moving):
            return "panels not fully open"
        if coil == PANELS_CLOSE and not (self.lift.at_low and not self.lift.moving):
            return "lift not fully down"
        return ""

    def _record(self, coil: int, accepted: bool, reason: str) -> None:
        self.interlock_refused = not accepted
        self.command_log.append(CommandRecord(self.t_sim, COIL_NAMES[coil], accepted, reason))

    def _stop_all(self) -> None:
        self.panels.stop()
        self.lift.stop()

    # --- time ----------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance the physics by `dt` simulated seconds."""
        self.t_sim += dt
        if self.panels.step(dt):
            self.faults |= FAULT_PANEL_STALL
        if self.lift.step(dt):
            self.faults |= FAULT_LIFT_STALL
        connected = self.lift.at_low and self.contacts_seated and not self.estop_active
        self.charger.step(dt, self.charger_enable, connected, self.charge_limit_ma)
        motor_w = 24.0 * (self.panels.current_ma + self.lift.current_ma) / 1000.0
        charge_w = self.charger.current_ma / 1000.0 * self.charger.voltage_v / 0.9
        self.power.step(dt, motor_w + charge_w, self.weather.raining())
        noise = self._rng.gauss(0.0, self.params.scale_noise_g)
        self.scale_g = max(0.0, self.params.scale_tare_g + self.pad_mass_g + noise)

    def tick_wall(self, wall_now: float) -> None:
        """Advance communication timing (heartbeat, watchdog) to wall time `wall_now`."""
        if self._wall_start is None:
            self._wall_start = wall_now
        self._wall_now = wall_now
        if not self.cpu_halted:
            ticks = int((wall_now - self._wall_start) / HEARTBEAT_PERIOD_S)
            self._heartbeat = ticks % 65536
        changed = self._watchdog_changed_at
        if changed is not None and wall_now - changed > WATCHDOG_TIMEOUT_S:
            if not self.faults & FAULT_WATCHDOG:
                self._stop_all()
                self.faults |= FAULT_WATCHDOG

    @property
    def watchdog_armed(self) -> bool:
        """Whether a master has written the watchdog register at least once."""
        return self._watchdog_changed_at is not None

    @property
    def heartbeat(self) -> int:
        """PLC_HEARTBEAT: wall-time 100 ms ticks since power-up, wrapping at 65535."""
        return self._heartbeat

    # --- register image ------------------------------------------------------------------

    def fault_bits(self) -> int:
        """FAULT_BITS: latched faults plus the live charger and weather-sensor bits."""
        bits = self.faults
        if self.charger.fault:
            bits |= FAULT_CHARGER
        if self.weather.sensor_fault:
            bits |= FAULT_WEATHER
        return bits

    def coils(self) -> list[bool]:
        """Coil image (command coils always read back 0: they are processed on write)."""
        image = [False] * N_COILS
        image[CHARGER_ENABLE] = self.charger_enable
        return image

    def discrete_inputs(self) -> list[bool]:
        """Discrete input image."""
        r = self.weather.reading()
        return [
            self.panels.at_high,
            self.panels.at_low,
            self.lift.at_high,
            self.lift.at_low,
            self.panels.moving,
            self.lift.moving,
            self.estop_active,
            (r.rain_mm_h > 0.0) and not r.sensor_fault,
            self.power.grid_present,
            self.contacts_seated,
            self.interlock_refused,
        ]

    def input_registers(self) -> list[int]:
        """Input register image (encodings of the spec)."""
        r = self.weather.reading()
        mass = max(0, min(0xFFFFFFFF, round(self.scale_g)))
        if r.sensor_fault:
            weather = [0, 0, 0, 0, 0, 0]
        else:
            weather = [
                _u16(r.wind_mps * 100),
                _u16(r.gust_mps * 100),
                _u16(r.direction_deg) % 360,
                _u16(r.rain_mm_h * 10),
                round(r.temperature_c * 10) & 0xFFFF,
                _u16(r.humidity_pct * 10),
            ]
        ch = self.charger
        soc = UNKNOWN_SOC
        if ch.uav_soc is not None and self.contacts_seated and self.lift.at_low:
            soc = _u16(ch.uav_soc * 1000)
        return [
            mass >> 16,
            mass & 0xFFFF,
            *weather,
            int(ChargerState(ch.state)),
            _u16(ch.current_ma),
            _u16(ch.voltage_v * 100),
            soc,
            _u16(self.power.soc * 1000),
            _u16(self.power.voltage * 100),
            _u16(self.power.solar_w),
            int(self.power.source),
            _u16(self.panels.position * 1000),
            _u16(self.lift.position * 1000),
            self.fault_bits(),
            self.heartbeat,
        ]

    def holding_registers(self) -> list[int]:
        """Holding register image."""
        return [self.watchdog_value, self.charge_limit_ma]

    def ground_truth(self) -> dict[str, object]:
        """Everything a test or an operator of the simulator may want to see, as plain JSON."""
        r = self.weather.reading()
        return {
            "t_sim": self.t_sim,
            "panels": {
                "position": self.panels.position,
                "moving": self.panels.moving,
                "current_ma": self.panels.current_ma,
                "jammed": self.panels.jammed,
            },
            "lift": {
                "position": self.lift.position,
                "moving": self.lift.moving,
                "current_ma": self.lift.current_ma,
                "jammed": self.lift.jammed,
            },
            "estop_active": self.estop_active,
            "cpu_halted": self.cpu_halted,
            "faults": self.fault_bits(),
            "interlock_refused": self.interlock_refused,
            "watchdog_armed": self.watchdog_armed,
            "pad": {
                "mass_g": self.pad_mass_g,
                "contacts_seated": self.contacts_seated,
                "scale_g": self.scale_g,
            },
            "charger": {
                "enabled": self.charger_enable,
                "state": int(self.charger.state),
                "current_ma": self.charger.current_ma,
                "voltage_v": self.charger.voltage_v,
                "uav_soc": self.charger.uav_soc,
                "fault": self.charger.fault,
                "limit_ma": self.charge_limit_ma,
            },
            "power": {
                "source": int(self.power.source),
                "bank_soc": self.power.soc,
                "solar_w": self.power.solar_w,
                "grid_present": self.power.grid_present,
            },
            "weather": r.__dict__,
            "can_vehicle_leave": self.can_vehicle_leave(),
            "commands": [c.__dict__ for c in self.command_log[-50:]],
        }
