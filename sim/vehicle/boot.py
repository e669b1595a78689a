"""Boot and reboot of the simulated autopilot: time since boot, pre-arm messages while booting, reboot.

As ArduPilot: after power-up the pre-arm checks fail (EKF not ready, no GPS fix, no home) for
`Habits.boot_s`; a failing check is announced as "PreArm: ..." when it changes and every 30 s
(AP_Arming's PREARM_DISPLAY_PERIOD); MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN is refused while armed,
otherwise the autopilot goes silent for `Habits.reboot_s`, then boots again: time_boot_ms starts
from 0, STABILIZE, the mission kept (it is in storage), every stream back to its boot rate.
"""

from __future__ import annotations

import math
from typing import Any

from sim.vehicle.constants import ACCEPTED, CRITICAL, FAILED, INFO, STABILIZE


class BootMixin:
    """Boot state of `Copter` (t, t_boot, rebooting_until, boots live on the copter)."""

    config: Any
    t: float
    t_boot: float
    wall_boot: float | None
    wall: float
    armed: bool
    mode: int
    failsafe: bool
    guidance: Any
    mission_current: int
    upload: Any
    outbox: list[tuple[Any, Any]]
    rebooting_until: float
    reboot_pending: bool
    boots: int
    _prearm_told: tuple[str | None, float]

    def text(self, severity: int, text: str, throttle_s: float = 0.0) -> None:
        """Queue a STATUSTEXT (implemented by Copter)."""
        raise NotImplementedError

    def init_boot(self) -> None:
        """Power-up: booted at t = 0, no reboot under way."""
        self.t_boot = 0.0  # simulated time of the last (re)boot
        self.wall_boot: float | None = None  # wall time of the last (re)boot (first tick)
        self.rebooting_until = 0.0  # wall time: silent until then
        self.reboot_pending = False
        self.boots = 0  # completed reboots; the server resets its links' streams on each
        self._prearm_told = (None, -math.inf)

    def booting_text(self) -> str | None:
        """The pre-arm failure ArduPilot reports while it boots (EKF, GPS, home), or None once armable."""
        h = self.config.habits
        since = self.t - self.t_boot
        if since >= h.boot_s or not h.prearm_texts:
            return None
        phase = min(int(since / h.boot_s * len(h.prearm_texts)), len(h.prearm_texts) - 1)
        return h.prearm_texts[phase]

    @property
    def time_boot_ms(self) -> int:
        """Milliseconds since the autopilot (re)booted, as its messages' time_boot_ms: wall ones,
        as a flight controller's clock whatever the speed factor, or simulated ones, as SITL's
        (`Habits.uptime`: at the speed factor, and behind the wall when starved). A uint32, as
        ArduPilot's `AP_HAL::millis()`: it wraps to 0 after 49.7 days. Until the first reboot it
        counts from `CopterConfig.powered_s` (a flight controller left on in its base)."""
        powered = self.config.powered_s if self.boots == 0 else 0.0
        if self.config.habits.uptime == "simulated":
            since = self.t - self.t_boot
        elif self.wall_boot is None:
            since = 0.0
        else:
            since = self.wall - self.wall_boot
        return round((powered + since) * 1000) & 0xFFFFFFFF

    def rebooting(self, wall: float) -> bool:
        """True while the autopilot is restarting (silent)."""
        return wall < self.rebooting_until

    def reboot(self) -> int:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: refused when armed (as ArduPilot), else restart."""
        if self.armed:
            self.text(CRITICAL, "Reboot refused: vehicle armed")
            return FAILED
        self.reboot_pending = True  # silent from the next tick, once the COMMAND_ACK is out
        return ACCEPTED

    def _boot_tick(self, wall: float) -> None:
        """Start a requested reboot, finish one that is over, announce pre-arm failures."""
        if self.wall_boot is None:
            self.wall_boot = wall
        if self.reboot_pending:
            self.reboot_pending = False
            self.rebooting_until = wall + self.config.habits.reboot_s
        if self.rebooting_until and not self.rebooting(wall):
            self._finish_reboot()
        self._report_prearm()

    def _finish_reboot(self) -> None:
        self.rebooting_until = 0.0
        self.t_boot = self.t
        self.wall_boot = self.wall
        self.boots += 1
        self.mode = STABILIZE
        self.failsafe = False
        self.guidance.mission_cleared()
        self.guidance.hold()
        self.mission_current = 0
        self.upload = None
        self._prearm_told = (None, -math.inf)
        self.outbox.clear()
        self.text(INFO, "ArduCopter (simulated) rebooted")

    def _report_prearm(self) -> None:
        """As ArduPilot: a failing pre-arm check is announced when it changes and every 30 s."""
        if self.armed:
            return
        reason = self.booting_text()
        last, when = self._prearm_told
        if reason is None:
            self._prearm_told = (None, when)
            return
        if reason != last or self.t - when >= 30.0:
            self._prearm_told = (reason, self.t)
            self.text(CRITICAL, f"PreArm: {reason}")
