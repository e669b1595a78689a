"""QGroundControl's altitude modes of a `.plan` item: what each means, which we take, what we write.

QGroundControl (src/MissionManager/SimpleMissionItem.cc, `QGroundControlQmlGlobal::AltMode`) saves
on every item that has an altitude three keys beside the MAVLink fields: `AltitudeMode`,
`Altitude` (the number typed in its editor, in that mode's reference) and `AMSLAltAboveTerrain`
(terrain + Altitude once its terrain query answered, else null). What it uploads is `frame` and
`params[6]`:

| AltitudeMode | meaning                  | frame | params[6] uploaded                          |
|--------------|--------------------------|-------|---------------------------------------------|
| 1            | relative to home         | 3     | = Altitude                                  |
| 2            | AMSL                     | 0     | = Altitude                                  |
| 3            | calculated above terrain | 0     | terrain + Altitude (AMSL); null until QGC's |
|              |                          |       | terrain query answered                      |
| 4            | terrain frame            | 10    | = Altitude, held above terrain by the       |
|              |                          |       | autopilot from its own terrain data         |

Without the keys (older files, flattened survey items) QGroundControl reads the mode from the frame.
We take 1 and 2 as they are (an AMSL item is checked against `plannedHomePosition`), 3 as the AMSL
altitude QGroundControl computed from its terrain data when the plan was saved (the autopilot flies
that altitude; nothing follows the terrain between items), and refuse 4 and frame 10: the autopilot
would need terrain data that Aerobase neither supplies nor checks (ArduPilot's terrain database is
fed by the ground station; QGroundControl offers no terrain frame for PX4 at all,
`Vehicle::supportsTerrainFrame`). A null altitude is refused, never read as 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from server.missions.items import (
    FRAME_GLOBAL,
    FRAME_GLOBAL_RELATIVE_ALT,
    FRAME_GLOBAL_TERRAIN_ALT,
    FRAME_NAMES,
    NAV_LAND,
    NAV_TAKEOFF,
)
from server.missions.validate import Problem

MODE_RELATIVE, MODE_AMSL, MODE_CALC_ABOVE_TERRAIN, MODE_TERRAIN_FRAME = 1, 2, 3, 4
MODE_LABELS = {
    MODE_RELATIVE: "relative to home",
    MODE_AMSL: "AMSL",
    MODE_CALC_ABOVE_TERRAIN: "terrain-calculated",
    MODE_TERRAIN_FRAME: "terrain frame",
}
# the frame QGroundControl uploads an item of each mode in
MODE_FRAMES = {
    MODE_RELATIVE: FRAME_GLOBAL_RELATIVE_ALT,
    MODE_AMSL: FRAME_GLOBAL,
    MODE_CALC_ABOVE_TERRAIN: FRAME_GLOBAL,
    MODE_TERRAIN_FRAME: FRAME_GLOBAL_TERRAIN_ALT,
}
# the mode QGroundControl reads from a frame when an item carries no AltitudeMode
FRAME_MODES = {
    FRAME_GLOBAL_RELATIVE_ALT: MODE_RELATIVE,
    FRAME_GLOBAL: MODE_AMSL,
    FRAME_GLOBAL_TERRAIN_ALT: MODE_TERRAIN_FRAME,
}
ALTITUDE_KEYS = ("AMSLAltAboveTerrain", "Altitude", "AltitudeMode")
# params[6] and Altitude of a mode 1/2 item are one number written twice; more is a contradiction
SAME_ALTITUDE_M = 1e-3
# these two take 0, 0 (QGroundControl writes 0, 0 or null) as "where the vehicle is"
POSITION_OPTIONAL = frozenset({NAV_TAKEOFF, NAV_LAND})
TERRAIN_REFUSAL = (
    "is not supported: the autopilot would hold the altitude above terrain from its own terrain "
    "data, which Aerobase neither supplies nor checks; save the item with AltitudeMode 1 "
    "(relative), 2 (AMSL) or 3 (terrain-calculated, resolved by QGroundControl)"
)


@dataclass(frozen=True)
class Source:
    """Where an item sits in the plan, for messages: its index, path and container."""

    index: int
    where: str
    # for a flattened item of a ComplexItem: its type and CameraCalc DistanceMode (an AltitudeMode)
    complex_kind: str | None = None
    distance_mode: Any = None

    @property
    def label(self) -> str:
        """ "item 5", or for a flattened item the complex item it sits in."""
        if self.complex_kind is not None:
            return f"item {self.index} (complex item {self.complex_kind!r}, {self.where_inner})"
        return f"item {self.index}"

    @property
    def where_inner(self) -> str:
        """ "flattened item 3" (the tail of `where`)."""
        tail = self.where.rsplit("[", 1)[-1].rstrip("]")
        return f"flattened item {tail}"


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    f = float(value)
    return f if math.isfinite(f) else None


def _mode_of(value: Any) -> int | None:
    """An AltitudeMode number 1..4, else None."""
    f = _num(value)
    return int(f) if f is not None and f == int(f) and 1 <= f <= 4 else None


def mode_text(mode: int, unresolved: bool = False, key: str = "AltitudeMode") -> str:
    """ "AltitudeMode 3, terrain-calculated, unresolved"."""
    text = f"{key} {mode}, {MODE_LABELS[mode]}"
    return f"{text}, unresolved" if unresolved else text


def read_altitude(
    raw: dict[str, Any],
    command: int,
    frame: int,
    params: list[float | None],
    src: Source,
) -> tuple[dict[str, Any], list[Problem]]:
    """The QGroundControl altitude keys of one positional item (to keep) and every problem with it.

    `frame` is the plain (non-_INT) number; `params` the seven, null as None.
    """
    problems: list[Problem] = []

    def refuse(where: str, what: str, value: Any = None, limit: Any = None) -> None:
        problems.append(
            Problem(
                f"{src.where}{where}",
                f"{src.label}: {what}",
                value,
                limit,
                index=src.index,
                command=command,
            )
        )

    kept: dict[str, Any] = {}
    for key in ("Altitude", "AMSLAltAboveTerrain"):
        if key in raw:
            if raw[key] is not None and _num(raw[key]) is None:
                refuse(f".{key}", f"{key} must be a number or null", raw[key])
            else:
                kept[key] = _num(raw[key])
    mode: int | None
    if "AltitudeMode" in raw:
        mode = _mode_of(raw["AltitudeMode"])
        if mode is None:
            refuse(
                ".AltitudeMode",
                "AltitudeMode must be 1 (relative to home), 2 (AMSL), 3 (terrain-calculated) "
                "or 4 (terrain frame)",
                raw["AltitudeMode"],
                [1, 2, 3, 4],
            )
            return kept, problems
        kept["AltitudeMode"] = mode
        expected = MODE_FRAMES[mode]
        if frame in FRAME_MODES and frame != expected:
            refuse(
                ".frame",
                f"AltitudeMode {mode} ({MODE_LABELS[mode]}) is uploaded in frame {expected} "
                f"{FRAME_NAMES[expected]}, "
                f"but the item has frame {frame} {FRAME_NAMES[frame]}",
                frame,
                expected,
            )
            return kept, problems
    elif (distance := _mode_of(src.distance_mode)) is not None and MODE_FRAMES[distance] == frame:
        # flattened items carry no AltitudeMode: their complex item's DistanceMode says it
        mode = distance
    else:
        mode = FRAME_MODES.get(frame)
    unresolved = mode == MODE_CALC_ABOVE_TERRAIN and params[6] is None
    if "AltitudeMode" in raw and mode is not None:
        described = mode_text(mode, unresolved)
    elif src.complex_kind is not None and mode is not None and mode == _mode_of(src.distance_mode):
        described = mode_text(mode, unresolved, key="DistanceMode")
    else:
        # the mode QGroundControl would read from the frame
        named = f"frame {frame} {FRAME_NAMES.get(frame, '')}".rstrip()
        described = f"{named}, {MODE_LABELS[mode]}" if mode is not None else named
    if mode == MODE_TERRAIN_FRAME or frame == FRAME_GLOBAL_TERRAIN_ALT:
        if "AltitudeMode" in raw:
            what = "AltitudeMode 4 (terrain frame, uploaded as MAV_FRAME 10 GLOBAL_TERRAIN_ALT)"
        elif mode == MODE_TERRAIN_FRAME and src.complex_kind is not None:
            what = "DistanceMode 4 (terrain frame): frame 10 GLOBAL_TERRAIN_ALT"
        else:
            what = "frame 10 GLOBAL_TERRAIN_ALT (terrain frame, AltitudeMode 4)"
        where = ".AltitudeMode" if "AltitudeMode" in raw else ".frame"
        refuse(where, f"{what} {TERRAIN_REFUSAL}", raw.get("AltitudeMode", frame))
        return kept, problems
    if params[6] is None:
        refuse(".params[6]", f"no altitude ({described})")
    if command not in POSITION_OPTIONAL and (params[4] is None or params[5] is None):
        refuse(".params[4]", "no position (latitude or longitude is null)", params[4:6])
    altitude = kept.get("Altitude")
    if (
        mode in (MODE_RELATIVE, MODE_AMSL)
        and altitude is not None
        and params[6] is not None
        and abs(altitude - params[6]) > SAME_ALTITUDE_M
    ):
        refuse(
            ".Altitude",
            f"Altitude {altitude:g} ({mode_text(mode)}) and params[6] {params[6]:g} disagree: "
            "QGroundControl writes one number in both",
            params[6],
            altitude,
        )
    return kept, problems


def needs_home(frame: int) -> bool:
    """True for an item whose altitude is AMSL and is checked against the plan's home."""
    return frame == FRAME_GLOBAL


def export_keys(frame: int, alt: float, kept: dict[str, Any] | None) -> dict[str, Any]:
    """`AMSLAltAboveTerrain`, `Altitude`, `AltitudeMode` of a positional item, as QGroundControl writes.

    `kept` holds the keys an imported item carried; used whole when given, else derived from
    the frame (3 relative, 0 AMSL, 10 terrain frame; any other frame as relative, as QGC does).
    """
    if kept is not None and _mode_of(kept.get("AltitudeMode")) is not None:
        return {
            "AMSLAltAboveTerrain": kept.get("AMSLAltAboveTerrain"),
            "Altitude": kept.get("Altitude", alt),
            "AltitudeMode": kept["AltitudeMode"],
        }
    return {
        "AMSLAltAboveTerrain": None,
        "Altitude": alt,
        "AltitudeMode": FRAME_MODES.get(frame, MODE_RELATIVE),
    }
