"""What a mission read back from the autopilot must still say: the comparison rules, per command.

Autopilots do not give back every field as sent. ArduPilot packs each item into a 15-byte
record (`AP_Mission::mavlink_int_to_mission_cmd`, read back by `mission_cmd_to_mavlink_int`):
a param it has no room for comes back 0, a param kept in an integer field comes back truncated
(NaN as 0), the altitude is kept in whole centimetres, a position only for commands that have
one, the frame as GLOBAL / GLOBAL_RELATIVE_ALT (never the _INT spelling), autocontinue as 1.
PX4 keeps the params each command uses as floats (NaN included; yaw converted to radians and
back) in `mission_item_s`, drops the others (TAKEOFF keeps only its yaw, LAND its precision mode
and yaw), and the position as double degrees, truncated (older releases) or rounded to 1e-7 on the
way back, in the _INT frame spelling (`MavlinkMissionManager::format_mavlink_mission_item`).

So a read-back item matches when (see README.md, "Mission verification"):
- the command is the same;
- the frame is the same, `_INT` and plain spellings being one frame; for commands without a
  position any frame is accepted (ArduPilot answers GLOBAL);
- for commands with a position: x and y within 1 (1e-7 degrees), z within 1 cm plus float32
  rounding; without a position x, y, z are not compared;
- each param: where we sent NaN ("the autopilot's default") any value is accepted; a param
  ArduPilot does not keep for that command is accepted whatever comes back (it is 0 there, as
  sent on PX4); a param kept in an integer field matches its truncation or its float32 value;
  every other param matches as float32 (relative 1e-5);
- autocontinue is not compared (ArduPilot always answers 1).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Literal

from asset_agent.autopilot.items import MissionItem

Kind = Literal["float", "int", "dropped"]
F: Kind = "float"
N: Kind = "int"  # kept in an integer field: truncated
X: Kind = "dropped"

# MAV_CMD -> how ArduPilot keeps param1..param4 (AP_Mission.cpp); commands not listed: float
PARAM_RULES: dict[int, tuple[Kind, Kind, Kind, Kind]] = {
    16: (N, X, X, X),  # NAV_WAYPOINT: hold time in cmd.p1 (uint16); radius, pass-by, yaw dropped
    17: (X, X, N, X),  # NAV_LOITER_UNLIM: radius magnitude in cmd.p1, sign as direction
    18: (N, X, N, N),  # NAV_LOITER_TURNS: turns (low byte), radius (high byte), xtrack flag
    19: (N, X, X, N),  # NAV_LOITER_TIME: seconds in cmd.p1; param3 back as the direction +-1
    20: (X, X, X, X),  # NAV_RETURN_TO_LAUNCH: nothing kept
    21: (X, X, X, X),  # NAV_LAND: abort alt (plane only; PX4 drops it), param4 back as +-1
    22: (X, X, X, X),  # NAV_TAKEOFF: pitch (plane only; PX4 drops it); ArduPilot drops the yaw
    82: (N, X, X, X),  # NAV_SPLINE_WAYPOINT: hold time in cmd.p1
    93: (F, N, N, N),  # NAV_DELAY: seconds (float), hour / minute / second (int8)
    112: (F, X, X, X),  # CONDITION_DELAY: seconds
    115: (F, F, N, N),  # CONDITION_YAW: angle, rate, direction (int8), relative (uint8)
    177: (N, N, X, X),  # DO_JUMP: target (uint16), repeat count (int16)
    178: (N, F, F, X),  # DO_CHANGE_SPEED: speed type (uint8), speed, throttle
    # fence items (AC_PolyFence_loader): a vertex keeps its polygon's vertex count (uint8), a
    # circle its radius (float, or uint32 when whole), a return point and a rally point no param
    5000: (X, X, X, X),  # NAV_FENCE_RETURN_POINT
    5001: (N, X, X, X),  # NAV_FENCE_POLYGON_VERTEX_INCLUSION
    5002: (N, X, X, X),  # NAV_FENCE_POLYGON_VERTEX_EXCLUSION
    5003: (F, X, X, X),  # NAV_FENCE_CIRCLE_INCLUSION
    5004: (F, X, X, X),  # NAV_FENCE_CIRCLE_EXCLUSION
    5100: (X, X, X, X),  # NAV_RALLY_POINT (its altitude kept in whole metres: send whole metres)
}
# MAV_CMDs that carry a position (AP_Mission::stored_in_location)
POSITIONAL = frozenset((16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 92, 94, 179, 189, 191, 201))
# fence and rally items carry a position too; a fence item's altitude is not kept (sent as 0)
POSITIONAL |= frozenset((5000, 5001, 5002, 5003, 5004, 5100))
# MAV_FRAME spellings that mean the same frame
SAME_FRAME = {5: 0, 6: 3, 11: 10, 2: 0}
ALT_TOLERANCE_M = 0.01  # ArduPilot keeps whole centimetres
FLOAT_TOLERANCE = 1e-5  # float32, and PX4's yaw kept in radians (degrees -> radians -> degrees)


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def _frame(f: int) -> int:
    return SAME_FRAME.get(f, f)


def param_matches(kind: Kind, sent: float, got: float) -> bool:
    """One param: sent -> read back, under the rule `kind`."""
    if math.isnan(sent) or kind == "dropped":
        return True
    if math.isnan(got):
        return False
    if abs(_f32(sent) - _f32(got)) <= FLOAT_TOLERANCE * max(1.0, abs(sent)):
        return True
    return kind == "int" and math.isfinite(sent) and float(math.trunc(sent)) == got


@dataclass(frozen=True)
class Mismatch:
    """Which field of a read-back item differs, with what was sent and what came back."""

    field: str
    sent: float
    got: float

    def __str__(self) -> str:
        return f"{self.field} differs after read-back: sent {self.sent!r}, read back {self.got!r}"


def compare(sent: MissionItem, got: MissionItem) -> Mismatch | None:
    """None when `got` is `sent` as the autopilot keeps it, else the first field that differs."""
    if sent.command != got.command:
        return Mismatch("command", sent.command, got.command)
    positional = sent.command in POSITIONAL
    if positional and _frame(sent.frame) != _frame(got.frame):
        return Mismatch("frame", sent.frame, got.frame)
    if positional:
        for name in ("x", "y"):
            a, b = getattr(sent, name), getattr(got, name)
            if abs(a - b) > 1:
                return Mismatch(name, a, b)
        if not abs(sent.z - got.z) <= ALT_TOLERANCE_M + abs(sent.z) * 1e-6:
            return Mismatch("z", sent.z, got.z)
    rules = PARAM_RULES.get(sent.command, (F, F, F, F))
    for i, kind in enumerate(rules, start=1):
        a, b = getattr(sent, f"param{i}"), getattr(got, f"param{i}")
        if not param_matches(kind, a, b):
            return Mismatch(f"param{i}", a, b)
    return None
