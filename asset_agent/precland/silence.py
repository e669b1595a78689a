"""Precision landing that sends nothing while its sensors' readings arrive says so at once.

A landing loop runs, frames or IR readings that see the pad keep arriving, and yet no
LANDING_TARGET has gone out for `window_s` wall seconds (wall, not sensor seconds: the sensors'
clock may be what is wrong): the autopilot is landing on GNSS alone while the log would say
precision landing is active. The
watch raises one `precland_silent` warning per such silence (a target sent ends it), and the
landing's counters go into the `landed` event; a landing that came down that way is followed by
a `landed_without_precision` event, on which the server alerts on the run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from asset_agent.events import Event
from asset_agent.precland.detect import Detections


@dataclass
class SilenceWatch:
    """Frames in, no target out, for `window_s` wall seconds: a warning event."""

    window_s: float = 2.0
    wall: Callable[[], float] = time.monotonic
    # this landing's counters (since `start`), for the warning and the `landed` event
    frames: int = 0
    ir_readings: int = 0
    targets: int = 0
    warnings: int = 0
    _active: bool = False
    _quiet_since: float = 0.0  # the landing's start or the last target sent
    _last_reading: float | None = None
    _warned: bool = False

    def start(self) -> None:
        """A landing loop started: its counters from zero."""
        self._active, self._warned = True, False
        self._quiet_since = self.wall()
        self.frames = self.ir_readings = self.targets = self.warnings = 0
        self._last_reading = None

    def stop(self) -> None:
        """The landing loop ended (its counters stay for the `landed` event)."""
        self._active = False

    def reading(self, source: str, found: bool = True) -> None:
        """A camera frame ("camera") or an IR reading arrived; `found`: it saw the pad (a sensor
        that sees no pad sends no target, rightly: only readings of the pad count here)."""
        if not self._active or not found:
            return
        if source == "camera":
            self.frames += 1
        else:
            self.ir_readings += 1
        self._last_reading = self.wall()

    def detections(self, _t: float, det: Detections) -> None:
        """The detector's answer on a camera frame: one that found the pad is a reading."""
        self.reading("camera", any(e is not None for e in (det.frame, det.pattern, det.aruco)))

    def sent(self) -> None:
        """A LANDING_TARGET went out."""
        self.targets += 1
        self._quiet_since = self.wall()
        self._warned = False

    def check(self, clock_epochs: int = 0, searching: bool = False) -> Event | None:
        """The warning, once per silence, when readings arrive and no target went out for
        `window_s`; `clock_epochs`: the sensors' clock restarts seen so far (for the detail).
        `searching`: the agent flies the vehicle itself (takeover.py), which is no silence."""
        now = self.wall()
        if searching:
            self._quiet_since = now
            return None
        if not self._active or self._warned or self._last_reading is None:
            return None
        quiet = now - self._quiet_since
        if quiet < self.window_s or now - self._last_reading > self.window_s:
            return None
        self._warned = True
        self.warnings += 1
        detail = {
            "silent_s": round(quiet, 1),
            "frames": self.frames,
            "ir_readings": self.ir_readings,
            "targets_sent": self.targets,
            "clock_epochs": clock_epochs,
        }
        return Event("precland_silent", MappingProxyType(detail))

    def blind_landing(self, path: str | None) -> Event | None:
        """`landed_without_precision` for a landing that came down while its sensors' readings
        arrived and no target went out (none at all, or a silence still told at touchdown),
        unless the landing's own rule chose the GNSS (`rtk-fallback`, `search-then-precision`
        are the search's: takeover.py)."""
        if path not in ("gnss", "precision") or not (self.frames or self.ir_readings):
            return None
        if self.targets and not self._warned:
            return None
        return Event("landed_without_precision", MappingProxyType(self.landed_detail()))

    def landed_detail(self) -> dict[str, Any]:
        """This landing's counters for the `landed` event."""
        return {
            "precland_frames": self.frames,
            "precland_ir_readings": self.ir_readings,
            "precland_targets": self.targets,
            "precland_warnings": self.warnings,
        }
