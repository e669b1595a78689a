"""The canonical mission item (1:1 with MAVLink MISSION_ITEM_INT) and the commands and frames we take.

An item is ``{command, frame, params: [p1, p2, p3, p4], lat, lon, alt, autocontinue}``: MAV_CMD and
MAV_FRAME numbers, degrees, metres. A null param is MAVLink's NaN ("leave unchanged"). Home is not
an item: index i of a mission's list is MAVLink seq i + 1 (seq 0 is home, added by the agent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

# MAV_FRAME numbers
FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_TERRAIN_ALT = 0, 2, 3, 10
# the _INT variants mean the same thing; we store the plain number (as QGroundControl writes)
FRAME_ALIASES = {5: FRAME_GLOBAL, 6: FRAME_GLOBAL_RELATIVE_ALT, 11: FRAME_GLOBAL_TERRAIN_ALT}
FRAME_NAMES = {
    FRAME_GLOBAL: "GLOBAL", FRAME_MISSION: "MISSION", FRAME_GLOBAL_RELATIVE_ALT: "GLOBAL_RELATIVE_ALT",
    FRAME_GLOBAL_TERRAIN_ALT: "GLOBAL_TERRAIN_ALT", 5: "GLOBAL_INT", 6: "GLOBAL_RELATIVE_ALT_INT",
    11: "GLOBAL_TERRAIN_ALT_INT",
}  # fmt: skip
POSITION_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_TERRAIN_ALT})

# MAV_CMD numbers
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME = 16, 17, 18, 19
NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, NAV_SPLINE_WAYPOINT = 20, 21, 22, 82
DO_JUMP, DO_CHANGE_SPEED, DO_SET_ROI_LOCATION, DO_SET_ROI = 177, 178, 195, 201
DO_SET_CAM_TRIGG_DIST = 206
NAV_DELAY, CONDITION_DELAY, CONDITION_YAW = 93, 112, 115


@dataclass(frozen=True)
class CommandSpec:
    """What we know of one MAV_CMD: its name, whether it flies somewhere, whether it uses lat/lon/alt."""

    name: str
    nav: bool
    positional: bool


COMMANDS: dict[int, CommandSpec] = {
    NAV_WAYPOINT: CommandSpec("NAV_WAYPOINT", True, True),
    NAV_LOITER_UNLIM: CommandSpec("NAV_LOITER_UNLIM", True, True),
    NAV_LOITER_TURNS: CommandSpec("NAV_LOITER_TURNS", True, True),
    NAV_LOITER_TIME: CommandSpec("NAV_LOITER_TIME", True, True),
    NAV_RETURN_TO_LAUNCH: CommandSpec("NAV_RETURN_TO_LAUNCH", True, False),
    NAV_LAND: CommandSpec("NAV_LAND", True, True),
    NAV_TAKEOFF: CommandSpec("NAV_TAKEOFF", True, True),
    NAV_SPLINE_WAYPOINT: CommandSpec("NAV_SPLINE_WAYPOINT", True, True),
    DO_JUMP: CommandSpec("DO_JUMP", False, False),
    DO_CHANGE_SPEED: CommandSpec("DO_CHANGE_SPEED", False, False),
    DO_SET_ROI_LOCATION: CommandSpec("DO_SET_ROI_LOCATION", False, True),
    DO_SET_ROI: CommandSpec("DO_SET_ROI", False, True),
    DO_SET_CAM_TRIGG_DIST: CommandSpec("DO_SET_CAM_TRIGG_DIST", False, False),
    # common in ArduPilot Copter plans; carried through as they are
    NAV_DELAY: CommandSpec("NAV_DELAY", True, False),
    CONDITION_DELAY: CommandSpec("CONDITION_DELAY", False, False),
    CONDITION_YAW: CommandSpec("CONDITION_YAW", False, False),
    181: CommandSpec("DO_SET_RELAY", False, False),
    183: CommandSpec("DO_SET_SERVO", False, False),
    197: CommandSpec("DO_SET_ROI_NONE", False, False),
    203: CommandSpec("DO_DIGICAM_CONTROL", False, False),
    205: CommandSpec("DO_MOUNT_CONTROL", False, False),
    2000: CommandSpec("IMAGE_START_CAPTURE", False, False),
    2001: CommandSpec("IMAGE_STOP_CAPTURE", False, False),
    530: CommandSpec("SET_CAMERA_MODE", False, False),
    2500: CommandSpec("VIDEO_START_CAPTURE", False, False),
    2501: CommandSpec("VIDEO_STOP_CAPTURE", False, False),
}

# a few names of commands we do not take, so an error can say what was refused
OTHER_COMMAND_NAMES = {
    30: "NAV_CONTINUE_AND_CHANGE_ALT", 31: "NAV_LOITER_TO_ALT", 84: "NAV_VTOL_TAKEOFF",
    85: "NAV_VTOL_LAND", 92: "NAV_GUIDED_ENABLE", 94: "NAV_PAYLOAD_PLACE",
    113: "CONDITION_CHANGE_ALT", 114: "CONDITION_DISTANCE", 179: "DO_SET_HOME",
    182: "DO_REPEAT_RELAY", 184: "DO_REPEAT_SERVO", 189: "DO_LAND_START",
    202: "DO_DIGICAM_CONFIGURE", 211: "DO_GRIPPER", 1000: "DO_GIMBAL_MANAGER_PITCHYAW",
}  # fmt: skip


def command_name(command: object) -> str:
    """A readable name of a MAV_CMD number (or of whatever was given instead)."""
    if isinstance(command, int) and not isinstance(command, bool):
        spec = COMMANDS.get(command)
        if spec:
            return spec.name
        return OTHER_COMMAND_NAMES.get(command, f"MAV_CMD {command}")
    return repr(command)


def normalize_frame(frame: int) -> int:
    """GLOBAL_INT, GLOBAL_RELATIVE_ALT_INT, GLOBAL_TERRAIN_ALT_INT -> their plain numbers."""
    return FRAME_ALIASES.get(frame, frame)


def frame_problem(command: int, frame: int) -> str | None:
    """Why `frame` cannot carry `command` (None when it can)."""
    spec = COMMANDS.get(command)
    frame = normalize_frame(frame)
    if frame not in FRAME_NAMES:
        return f"frame {frame} is not supported (use 0 GLOBAL, 3 GLOBAL_RELATIVE_ALT or 10 GLOBAL_TERRAIN_ALT)"
    if spec is not None and spec.nav and spec.positional and frame not in POSITION_FRAMES:
        return f"{spec.name} needs a global frame (0, 3 or 10), not {frame} {FRAME_NAMES[frame]}"
    return None


class MissionItem(BaseModel):
    """One mission item, exactly the fields of MAVLink MISSION_ITEM_INT (lat/lon in degrees)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)
    command: int = Field(ge=0, le=65535, description="MAV_CMD number, e.g. 16 NAV_WAYPOINT")
    frame: int = Field(
        default=FRAME_GLOBAL_RELATIVE_ALT,
        ge=0,
        le=255,
        description="MAV_FRAME number: 0 GLOBAL, 2 MISSION, 3 GLOBAL_RELATIVE_ALT, "
        "10 GLOBAL_TERRAIN_ALT (5, 6, 11 are stored as 0, 3, 10)",
    )
    params: tuple[float | None, float | None, float | None, float | None] = Field(
        default=(0.0, 0.0, 0.0, 0.0), description="param1..param4; null = NaN (leave unchanged)"
    )
    lat: float = Field(default=0.0, description="degrees (WGS84)")
    lon: float = Field(default=0.0, description="degrees (WGS84)")
    alt: float = Field(default=0.0, description="metres, in the frame's reference")
    autocontinue: bool = True

    def normalized(self) -> MissionItem:
        """The same item with its frame stored as the plain (non-_INT) number."""
        frame = normalize_frame(self.frame)
        return self if frame == self.frame else self.model_copy(update={"frame": frame})

    @property
    def spec(self) -> CommandSpec | None:
        """What we know of this item's command (None: not supported)."""
        return COMMANDS.get(self.command)


def param(value: object) -> float | None:
    """A param as we store it: a finite float, or None for NaN/null."""
    if value is None:
        return None
    f = float(value)  # type: ignore[arg-type]
    return None if math.isnan(f) else f


def item_dicts(items: list[MissionItem]) -> list[dict[str, object]]:
    """Items as JSON-ready dicts (the shape stored, returned and sent to the UAV agent)."""
    return [i.model_dump(mode="json") for i in items]


def items_of(dicts: list[dict[str, object]]) -> list[MissionItem]:
    """Stored dicts back into items."""
    return [MissionItem.model_validate(d) for d in dicts]
