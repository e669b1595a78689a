"""Pure LANDING_TARGET handling as ArduPilot's precision landing does with PLND_TYPE=1.

Accepted frames: MAV_FRAME_BODY_FRD (12, rotated by roll, pitch and yaw) and
MAV_FRAME_LOCAL_FRD (20, rotated by yaw only); any other frame is rejected. A reading gives a
line of sight, either from the angles (ArduPilot: los = (-tan(angle_y), tan(angle_x), 1)) or,
when position_valid is set, from the position x, y, z with distance > 0 (only the direction is
used). The line of sight is scaled by the height above ground to a target position. A reading
steers the vehicle for `fresh_s` (1 s); with no reading for `lost_s` (2 s) the target is lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20
ACCEPTED_FRAMES = (MAV_FRAME_BODY_FRD, MAV_FRAME_LOCAL_FRD)


@dataclass(frozen=True)
class TargetReading:
    """The fields of one LANDING_TARGET message that matter."""

    frame: int
    angle_x: float = 0.0
    angle_y: float = 0.0
    distance: float = 0.0
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    position_valid: bool = False


def _rotate(v: tuple[float, float, float], roll: float, pitch: float, yaw: float):
    x, y, z = v
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    )  # fmt: skip
    # R = Rz(yaw) Ry(pitch) Rx(roll), body FRD -> NED
    n = cy * cp * x + (cy * sp * sr - sy * cr) * y + (cy * sp * cr + sy * sr) * z
    e = sy * cp * x + (sy * sp * sr + cy * cr) * y + (sy * sp * cr - cy * sr) * z
    d = -sp * x + cp * sr * y + cp * cr * z
    return n, e, d


def line_of_sight_ned(
    r: TargetReading, roll: float, pitch: float, yaw: float
) -> tuple[float, float, float] | str:
    """The unit line of sight to the target in NED, or the reason the reading is rejected."""
    if r.frame not in ACCEPTED_FRAMES:
        return f"Plnd: Frame not supported ({r.frame})"
    if r.position_valid:
        if not r.distance > 0:
            return "Plnd: distance must be > 0"
        los = (r.x / r.distance, r.y / r.distance, r.z / r.distance)
    else:
        los = (-math.tan(r.angle_y), math.tan(r.angle_x), 1.0)
    if r.frame == MAV_FRAME_LOCAL_FRD:
        roll = pitch = 0.0
    n, e, d = _rotate(los, roll, pitch, yaw)
    norm = math.sqrt(n * n + e * e + d * d)
    if norm == 0 or d / norm < 0.1:
        return "Plnd: target not below"
    return n / norm, e / norm, d / norm


class PrecisionLanding:
    """Tracks the landing target: `handle` readings, ask `target_ne(now)` where to land."""

    def __init__(self, fresh_s: float = 1.0, lost_s: float = 2.0) -> None:
        self.fresh_s = fresh_s
        self.lost_s = lost_s
        self._target: tuple[float, float] | None = None
        self._time: float | None = None
        self.accepted = 0
        self.rejected = 0
        self.was_acquired = False

    def handle(
        self,
        reading: TargetReading,
        now: float,
        position_ne: tuple[float, float],
        height_m: float,
        attitude: tuple[float, float, float],
    ) -> str | None:
        """Use one reading taken at `now` at the vehicle's estimated position; a rejection reason or None."""
        los = line_of_sight_ned(reading, *attitude)
        if isinstance(los, str):
            self.rejected += 1
            return los
        scale = max(height_m, 0.0) / los[2]
        self._target = (position_ne[0] + los[0] * scale, position_ne[1] + los[1] * scale)
        self._time = now
        self.accepted += 1
        self.was_acquired = True
        return None

    def fresh(self, now: float) -> bool:
        """True when the last reading is younger than `fresh_s`."""
        return self._time is not None and now - self._time <= self.fresh_s

    def lost(self, now: float) -> bool:
        """True when there was a target and no reading came for `lost_s`."""
        return self._time is not None and now - self._time > self.lost_s

    def target_ne(self, now: float) -> tuple[float, float] | None:
        """Where the target is (estimated NED), or None when there is none or it is lost."""
        if self._target is None or self.lost(now):
            return None
        return self._target

    def reset(self) -> None:
        """Forget the target (new landing)."""
        self._target = self._time = None
        self.was_acquired = False
