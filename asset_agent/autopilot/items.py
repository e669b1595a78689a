"""Mission items: the server's dict format <-> MISSION_ITEM_INT fields, with range validation.

The server sends a list of dicts ``{command, frame, params: [p1, p2, p3, p4], lat, lon, alt,
autocontinue}`` (MAV_CMD and MAV_FRAME numbers, degrees, metres). Index i of that list is
MAVLink seq i + 1: seq 0 is home, which the adapter adds on upload and drops on download,
as ArduPilot expects.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from asset_agent.autopilot.errors import InvalidMissionItem

# MAV_FRAMEs a mission item may use
FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT = 0, 2, 3
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT, FRAME_GLOBAL_TERRAIN_ALT = 5, 6, 10
FRAME_GLOBAL_TERRAIN_ALT_INT = 11
ITEM_FRAMES = (
    FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_INT,
    FRAME_GLOBAL_RELATIVE_ALT_INT, FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT,
)  # fmt: skip
MAX_ALT_M = 10_000.0
MIN_ALT_M = -1_000.0


@dataclass(frozen=True)
class MissionItem:
    """One mission item in MISSION_ITEM_INT terms: x, y are degrees * 1e7, z metres."""

    command: int
    frame: int = FRAME_GLOBAL_RELATIVE_ALT_INT
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    autocontinue: int = 1


def _number(index: int, d: Mapping[str, Any], key: str, default: float | None = None) -> float:
    value = d.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidMissionItem(index, f"{key} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise InvalidMissionItem(index, f"{key} must be finite, got {value!r}")
    return float(value)


def item_from_dict(index: int, d: Mapping[str, Any]) -> MissionItem:
    """One server dict -> MissionItem, or InvalidMissionItem naming the index and the field."""
    if not isinstance(d, Mapping):
        raise InvalidMissionItem(index, "an item must be an object")
    command = d.get("command")
    if isinstance(command, bool) or not isinstance(command, int) or not 0 < command <= 65535:
        raise InvalidMissionItem(index, f"command must be a MAV_CMD number, got {command!r}")
    frame = d.get("frame", FRAME_GLOBAL_RELATIVE_ALT_INT)
    if isinstance(frame, bool) or frame not in ITEM_FRAMES:
        raise InvalidMissionItem(index, f"frame {frame!r} is not a mission frame {ITEM_FRAMES}")
    params = d.get("params", [0.0, 0.0, 0.0, 0.0])
    if not isinstance(params, list | tuple) or len(params) != 4:
        raise InvalidMissionItem(index, "params must be a list of 4 numbers")
    # NaN (or null) is MAVLink's "leave unchanged", e.g. the yaw of a takeoff
    p = [math.nan if v is None or (isinstance(v, float) and math.isnan(v)) else v for v in params]
    p = [
        v if isinstance(v, float) and math.isnan(v) else _number(index, {"params": v}, "params")
        for v in p
    ]
    lat = _number(index, d, "lat", 0.0)
    lon = _number(index, d, "lon", 0.0)
    alt = _number(index, d, "alt", 0.0)
    if not -90.0 <= lat <= 90.0:
        raise InvalidMissionItem(index, f"lat {lat} out of range [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise InvalidMissionItem(index, f"lon {lon} out of range [-180, 180]")
    if not MIN_ALT_M <= alt <= MAX_ALT_M:
        raise InvalidMissionItem(index, f"alt {alt} out of range [{MIN_ALT_M}, {MAX_ALT_M}]")
    autocontinue = d.get("autocontinue", True)
    if not isinstance(autocontinue, bool | int):
        raise InvalidMissionItem(index, "autocontinue must be a boolean")
    return MissionItem(
        command, frame, p[0], p[1], p[2], p[3], round(lat * 1e7), round(lon * 1e7), alt,
        int(bool(autocontinue)),
    )  # fmt: skip


def items_from_dicts(dicts: Iterable[Mapping[str, Any]]) -> list[MissionItem]:
    """The server's list -> MissionItems; the first bad item raises InvalidMissionItem."""
    if isinstance(dicts, str | bytes) or not isinstance(dicts, Iterable):
        raise InvalidMissionItem(None, "a mission must be a list of items")
    return [item_from_dict(i, d) for i, d in enumerate(dicts)]


def item_to_dict(item: MissionItem) -> dict[str, Any]:
    """MissionItem -> the server's dict format."""
    return {
        "command": item.command,
        "frame": item.frame,
        "params": [
            None if math.isnan(p) else p
            for p in (item.param1, item.param2, item.param3, item.param4)
        ],
        "lat": item.x / 1e7,
        "lon": item.y / 1e7,
        "alt": item.z,
        "autocontinue": bool(item.autocontinue),
    }


def items_to_dicts(items: Iterable[MissionItem]) -> list[dict[str, Any]]:
    """MissionItems -> the server's list format."""
    return [item_to_dict(i) for i in items]
