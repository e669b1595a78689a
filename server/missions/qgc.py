"""QGroundControl `.plan` files (JSON) to mission items (the export is qgc_export.py). Pure functions.

Import takes every SimpleItem, and the flattened simple items QGroundControl stores inside a
ComplexItem (`TransectStyleComplexItem.Items`); anything else is named in a `Problem` by index
and command, never dropped. Altitudes are read as QGroundControl means them (qgc_altitude.py).
Geofence and rally points are carried through untouched; so are the plan's `doJumpId`s, altitude
keys, speeds, firmware and vehicle type (in `extras["qgc"]`), for the export to write them back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from server.missions.items import (
    COMMANDS,
    DO_JUMP,
    MissionItem,
    command_name,
    frame_problem,
    normalize_frame,
)
from server.missions.json_numbers import non_finite_numbers
from server.missions.qgc_altitude import (
    MODE_LABELS,
    Source,
    needs_home,
    read_altitude,
)
from server.missions.validate import Home, Problem

FIRMWARE_ARDUPILOT = 3
VEHICLE_MULTIROTOR = 2
MULTIROTOR_TYPES = {2, 3, 4, 13, 14, 15}  # MAV_TYPE quad, coaxial, heli, hexa, octo, tri
DEFAULT_CRUISE_MPS, DEFAULT_HOVER_MPS = 15.0, 5.0
# mission-level keys of a plan kept for the export (numbers only)
KEPT_MISSION_KEYS = (
    "cruiseSpeed",
    "firmwareType",
    "globalPlanAltitudeMode",
    "hoverSpeed",
    "vehicleType",
)


@dataclass(frozen=True)
class Imported:
    """A mission read from a file: its items, home, speed and anything carried through."""

    items: list[MissionItem]
    home: Home | None = None
    speed_mps: float | None = None
    extras: dict[str, Any] = field(default_factory=dict)


class ImportRejected(Exception):
    """A file holds items (or parts) we cannot take; `problems` names every one."""

    def __init__(self, problems: list[Problem]) -> None:
        super().__init__(f"{len(problems)} problem(s) in the file")
        self.problems = problems


@dataclass(frozen=True)
class _Found:
    """One item taken from the plan, with what it carried that our item has no field for."""

    item: MissionItem
    jump_id: Any
    kept: dict[str, Any]
    src: Source


def plan_number(value: Any) -> float | None:
    """A JSON number as a finite float; None for null or non-numbers/NaN."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        f = float(value)
    except OverflowError:  # an integer beyond the range of a double
        return None
    return f if math.isfinite(f) else None


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _simple(raw: Any, src: Source, problems: list[Problem]) -> _Found | None:
    """One SimpleItem -> _Found, or a Problem appended."""
    index, where = src.index, src.where
    if not isinstance(raw, dict):
        problems.append(
            Problem(where, "an item must be a JSON object", type(raw).__name__, index=index)
        )
        return None
    command = raw.get("command")
    if not isinstance(command, int) or isinstance(command, bool) or not 0 <= command <= 65535:
        problems.append(
            Problem(f"{where}.command", "command must be a MAV_CMD number", command, index=index)
        )
        return None
    if command not in COMMANDS:
        problems.append(
            Problem(
                f"{where}.command",
                f"unsupported command {command_name(command)}",
                command,
                sorted(COMMANDS),
                index=index,
                command=command,
            )
        )
        return None
    frame = raw.get("frame")
    if not isinstance(frame, int) or isinstance(frame, bool) or frame_problem(command, frame):
        why = (
            frame_problem(command, frame)
            if isinstance(frame, int) and not isinstance(frame, bool)
            else "frame must be a MAV_FRAME number"
        )
        problems.append(Problem(f"{where}.frame", str(why), frame, index=index, command=command))
        return None
    params = raw.get("params")
    if not isinstance(params, list) or len(params) != 7:
        problems.append(
            Problem(
                f"{where}.params",
                "params must be a list of 7 numbers or nulls",
                None if not isinstance(params, list) else len(params),
                7,
                index=index,
                command=command,
            )
        )
        return None
    bad = [k for k, p in enumerate(params) if p is not None and plan_number(p) is None]
    if bad:
        problems.append(
            Problem(
                f"{where}.params[{bad[0]}]",
                "params must be finite numbers or null",
                params[bad[0]],
                index=index,
                command=command,
            )
        )
        return None
    values = [plan_number(p) for p in params]
    kept: dict[str, Any] = {}
    if COMMANDS[command].positional:
        kept, refused = read_altitude(raw, command, normalize_frame(frame), values, src)
        if refused:
            problems += refused
            return None
    auto = raw.get("autoContinue", True)
    item = MissionItem(
        command=command,
        frame=normalize_frame(frame),
        params=(values[0], values[1], values[2], values[3]),
        # a positional item's nulls were refused above (take-off and land: 0, 0 is "here");
        # a non-positional item does not use lat/lon/alt
        lat=values[4] or 0.0,
        lon=values[5] or 0.0,
        alt=values[6] or 0.0,
        autocontinue=bool(auto) if isinstance(auto, bool) else True,
    )
    return _Found(item, raw.get("doJumpId"), kept, src)


def parse_plan(plan: Any) -> Imported:
    """A `.plan` document -> Imported; raises ImportRejected naming every item it cannot take."""
    if not isinstance(plan, dict):
        raise ImportRejected(
            [Problem("plan", "a .plan file is a JSON object", type(plan).__name__)]
        )
    numbers = non_finite_numbers(plan)
    if numbers:
        # refused before anything reads them: they cannot be stored, checked or sent back as JSON
        raise ImportRejected(numbers)
    problems: list[Problem] = []
    if plan.get("fileType") != "Plan":
        problems.append(
            Problem(
                "fileType",
                'not a QGroundControl plan (fileType must be "Plan")',
                plan.get("fileType"),
                "Plan",
            )
        )
    mission = plan.get("mission")
    if not isinstance(mission, dict) or not isinstance(mission.get("items"), list):
        problems.append(Problem("mission.items", "the plan has no mission items list", None))
        raise ImportRejected(problems)
    found: list[_Found] = []
    for i, raw in enumerate(mission["items"]):
        where = f"mission.items[{i}]"
        kind = raw.get("type") if isinstance(raw, dict) else None
        if kind == "SimpleItem":
            one = _simple(raw, Source(i, where), problems)
            if one:
                found.append(one)
        elif kind == "ComplexItem":
            found += _complex(raw, i, where, problems)
        else:
            problems.append(
                Problem(
                    f"{where}.type",
                    "unknown item type (SimpleItem or ComplexItem)",
                    kind,
                    index=i,
                    command=raw.get("command") if isinstance(raw, dict) else None,
                )
            )
    items = _resolve_jumps(found, problems)
    home = _home(mission.get("plannedHomePosition"), problems)
    if mission.get("plannedHomePosition") is None:
        problems += _amsl_without_home(found)
    if problems:
        raise ImportRejected(problems)
    vehicle = mission.get("vehicleType")
    speed = plan_number(
        mission.get(
            "hoverSpeed" if vehicle in MULTIROTOR_TYPES or vehicle is None else "cruiseSpeed"
        )
    )
    extras: dict[str, Any] = {
        k: plan[k] for k in ("geoFence", "rallyPoints") if isinstance(plan.get(k), dict)
    }
    extras["qgc"] = _kept(mission, found)
    return Imported(
        items=items, home=home, speed_mps=speed if speed and speed > 0 else None, extras=extras
    )


def _kept(mission: dict[str, Any], found: list[_Found]) -> dict[str, Any]:
    """What the export writes back: the plan's mission keys and, per item, what it carried.

    Each item's entry names the command, frame and altitude it was read with, so the export
    uses it only while the item is still that item.
    """
    kept: dict[str, Any] = {
        k: mission[k] for k in KEPT_MISSION_KEYS if plan_number(mission.get(k)) is not None
    }
    kept["items"] = [
        {
            **f.kept,
            "doJumpId": f.jump_id if _is_int(f.jump_id) else None,
            "command": f.item.command,
            "frame": f.item.frame,
            "alt": f.item.alt,
        }
        for f in found
    ]
    return kept


def _amsl_without_home(found: list[_Found]) -> list[Problem]:
    """AMSL items of a plan without plannedHomePosition: nothing to check their height against."""
    return [
        Problem(
            f"{f.src.where}.frame",
            f"{f.src.label}: {_amsl_mode(f)} needs the plan's plannedHomePosition "
            "to be checked against home, and the plan has none",
            f.item.alt,
            index=f.src.index,
            command=f.item.command,
        )
        for f in found
        if f.item.spec is not None and f.item.spec.positional and needs_home(f.item.frame)
    ]


def _amsl_mode(found: _Found) -> str:
    """ "AltitudeMode 3 (terrain-calculated, AMSL)" or, without the key, the frame."""
    mode = found.kept.get("AltitudeMode")
    if mode in MODE_LABELS:
        label = MODE_LABELS[mode]
        return f"AltitudeMode {mode} ({label if mode == 2 else f'{label}, AMSL'})"
    return "frame 0 GLOBAL (AMSL)"


def _complex(raw: dict[str, Any], i: int, where: str, problems: list[Problem]) -> list[_Found]:
    kind = raw.get("complexItemType")
    # survey, corridor and structure scans keep their flattened items in TransectStyleComplexItem;
    # other styles (e.g. AgriculturalStyleComplexItem) in a section of their own, with the same key
    sections = [raw.get("TransectStyleComplexItem")] + [
        v for v in raw.values() if isinstance(v, dict)
    ]
    section: dict[str, Any] | None = next(
        (s for s in sections if isinstance(s, dict) and isinstance(s.get("Items"), list)), None
    )
    if section is None or not section["Items"]:
        problems.append(
            Problem(
                where,
                f"complex item {kind!r} carries no flattened items "
                "(TransectStyleComplexItem.Items); re-save it from QGroundControl "
                "or convert it to waypoints",
                kind,
                index=i,
            )
        )
        return []
    out = []
    name = "TransectStyleComplexItem" if section is raw.get("TransectStyleComplexItem") else None
    name = name or next(k for k, v in raw.items() if v is section)
    for k, sub in enumerate(section["Items"]):
        src = Source(
            i,
            f"{where}.{name}.Items[{k}]",
            complex_kind=str(kind),
            distance_mode=_distance_mode(section),
        )
        one = _simple(sub, src, problems)
        if one:
            out.append(one)
    return out


def _distance_mode(section: dict[str, Any]) -> Any:
    """The AltitudeMode a transect's items were built in (CameraCalc.DistanceMode; v1 FollowTerrain)."""
    camera = section.get("CameraCalc")
    if isinstance(camera, dict) and "DistanceMode" in camera:
        return camera["DistanceMode"]
    if section.get("FollowTerrain") is True:
        return 3
    return None


def _resolve_jumps(found: list[_Found], problems: list[Problem]) -> list[MissionItem]:
    """DO_JUMP targets are doJumpIds in a plan; ours are seq numbers (index + 1)."""
    seq_of: dict[int, list[int]] = {}
    for n, f in enumerate(found):
        if _is_int(f.jump_id):
            seq_of.setdefault(f.jump_id, []).append(n + 1)
    items = []
    for n, f in enumerate(found):
        item = f.item
        if item.command == DO_JUMP and item.params[0] is not None:
            target = item.params[0]
            seqs = seq_of.get(int(target), []) if target == int(target) else []
            if len(seqs) != 1:
                problems.append(
                    Problem(
                        f"items[{n}].params[0]",
                        "DO_JUMP target is no item's doJumpId"
                        if not seqs
                        else f"DO_JUMP target doJumpId is carried by {len(seqs)} items",
                        target,
                        index=n,
                        command=DO_JUMP,
                    )
                )
            else:
                p = item.params
                item = item.model_copy(update={"params": (float(seqs[0]), p[1], p[2], p[3])})
        items.append(item)
    return items


def _home(raw: Any, problems: list[Problem]) -> Home | None:
    if raw is None:
        return None
    values = [plan_number(v) for v in raw] if isinstance(raw, list) and len(raw) == 3 else None
    if values is None or values[0] is None or values[1] is None:
        problems.append(Problem("mission.plannedHomePosition", "must be [lat, lon, alt]", raw))
        return None
    if values[2] is None:
        # AMSL items are checked against it: a home altitude is never assumed to be 0
        problems.append(
            Problem(
                "mission.plannedHomePosition[2]",
                "the planned home has no altitude (null); give its altitude above mean sea level",
                raw[2],
            )
        )
        return None
    return Home(values[0], values[1], values[2])
