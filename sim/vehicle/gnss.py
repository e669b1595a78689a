"""Pure GNSS receiver model: 3D fix with metre-level random walk, RTK float/fixed on corrections.

The error is a unit-variance Ornstein-Uhlenbeck process per axis scaled by the sigma of the
current fix, so a fix change rescales the error at once. Corrections are counted on the
caller's clock (the simulator uses wall time, as corrections arrive on wall time).
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass

FIX_NONE, FIX_2D, FIX_3D, FIX_DGPS, FIX_RTK_FLOAT, FIX_RTK_FIXED = 1, 2, 3, 4, 5, 6


@dataclass(frozen=True)
class GnssParams:
    """Noise levels and the correction rules."""

    sigma_3d_m: float = 1.2
    sigma_float_m: float = 0.25
    sigma_fixed_m: float = 0.012
    vertical_factor: float = 1.5
    correlation_s: float = 30.0  # random-walk time constant (simulated seconds)
    smoothing_s: float = 3.0  # low-pass on the walk so the error drifts instead of jittering
    fresh_window_s: float = 3.0  # a valid correction counts this long
    fixed_after_s: float = 2.0  # corrections flowing this long -> fixed
    satellites: int = 14
    satellites_rtk: int = 21


@dataclass(frozen=True)
class GnssReading:
    """What the receiver reports: fix type, error vector (NED metres), satellites, hdop."""

    fix_type: int
    error_ned: tuple[float, float, float]
    satellites: int
    hdop: float
    h_acc_m: float


class GnssModel:
    """The receiver: feed `correction(now)` for each valid RTCM frame, `step(dt, now)` to read."""

    def __init__(self, params: GnssParams | None = None, seed: int | None = None) -> None:
        self.params = params or GnssParams()
        self._rng = random.Random(seed)
        self._unit = [self._rng.gauss(0, 1) for _ in range(3)]
        self._smooth = list(self._unit)
        self._valid: deque[float] = deque()
        self._flow_since: float | None = None
        self.has_fix = True  # fault injection: False -> no fix
        self.bias_ne_m = (
            0.0,
            0.0,
        )  # fault injection: a steady position error (multipath, wrong datum)
        self.valid_frames = 0
        self.bad_frames = 0

    def correction(self, now: float, valid: bool) -> None:
        """Record one RTCM frame received at `now`, valid (CRC ok) or not."""
        if not valid:
            self.bad_frames += 1
            return
        self.valid_frames += 1
        self._valid.append(now)

    def fix_type(self, now: float) -> int:
        """The fix type at `now`."""
        p = self.params
        if not self.has_fix:
            return FIX_NONE
        while self._valid and now - self._valid[0] > p.fresh_window_s:
            self._valid.popleft()
        if not self._valid:
            self._flow_since = None
            return FIX_3D
        if self._flow_since is None:
            self._flow_since = self._valid[0]
        return FIX_RTK_FIXED if now - self._flow_since >= p.fixed_after_s else FIX_RTK_FLOAT

    def sigma(self, fix: int) -> float:
        """Horizontal 1-sigma error for a fix type."""
        p = self.params
        return {FIX_RTK_FIXED: p.sigma_fixed_m, FIX_RTK_FLOAT: p.sigma_float_m}.get(
            fix, p.sigma_3d_m
        )

    def step(self, dt: float, now: float) -> GnssReading:
        """Advance the random walk by `dt` simulated seconds; the reading at wall time `now`."""
        p = self.params
        if dt > 0:
            a = math.exp(-dt / p.correlation_s)
            b = math.sqrt(1 - a * a)
            self._unit = [a * u + b * self._rng.gauss(0, 1) for u in self._unit]
            # receivers filter: the reported error is a smoothed walk, not white jitter
            k = min(1.0, dt / p.smoothing_s)
            self._smooth = [s + (u - s) * k for s, u in zip(self._smooth, self._unit, strict=True)]
        return self.reading(now)

    def reading(self, now: float) -> GnssReading:
        """The current reading without advancing the random walk."""
        p = self.params
        fix = self.fix_type(now)
        s = self.sigma(fix)
        u = self._smooth
        err = (
            u[0] * s + self.bias_ne_m[0],
            u[1] * s + self.bias_ne_m[1],
            u[2] * s * p.vertical_factor,
        )
        rtk = fix >= FIX_RTK_FLOAT
        sats = 0 if fix == FIX_NONE else p.satellites_rtk if rtk else p.satellites
        hdop = 99.99 if fix == FIX_NONE else 0.6 if rtk else 0.9
        return GnssReading(fix, err, sats, hdop, s)
