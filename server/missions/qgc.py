"""QGroundControl `.plan` files (JSON) to and from mission items. Pure functions.

Import takes every SimpleItem, and the flattened simple items QGroundControl stores inside a
ComplexItem (`TransectStyleComplexItem.Items`); anything else is named in a `Problem` by index
and command, never dropped. Geofence and rally points are carried through untouched.
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
from server.missions.validate import Home, Problem

FIRMWARE_ARDUPILOT = 3
VEHICLE_MULTIROTOR = 2
MULTIROTOR_TYPES = {2, 3, 4, 13, 14, 15}  # MAV_TYPE quad, coaxial, heli, hexa, octo, tri
DEFAULT_CRUISE_MPS, DEFAULT_HOVER_MPS = 15.0, 5.0
# QGroundControl's AltitudeMode of a positional item: 1 relative, 2 absolute (AMSL), 4 terrain frame
ALTITUDE_MODES = {3: 1, 0: 2, 10: 4}


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


def _num(value: Any) -> float | None:
    """A JSON number as a finite float; None for null or non-numbers/NaN."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    f = float(value)
    return f if math.isfinite(f) else None


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _simple(
    raw: Any, index: int, where: str, problems: list[Problem]
) -> tuple[MissionItem, Any] | None:
    """One SimpleItem -> (item, doJumpId), or a Problem appended."""
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
    bad = [k for k, p in enumerate(params) if p is not None and _num(p) is None]
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
    values = [_num(p) for p in params]
    auto = raw.get("autoContinue", True)
    item = MissionItem(
        command=command,
        frame=normalize_frame(frame),
        params=(values[0], values[1], values[2], values[3]),
        lat=values[4] or 0.0,
        lon=values[5] or 0.0,
        alt=values[6] or 0.0,
        autocontinue=bool(auto) if isinstance(auto, bool) else True,
    )
    return item, raw.get("doJumpId")


def parse_plan(plan: Any) -> Imported:
    """A `.plan` document -> Imported; raises ImportRejected naming every item it cannot take."""
    if not isinstance(plan, dict):
        raise ImportRejected(
            [Problem("plan", "a .plan file is a JSON object", type(plan).__name__)]
        )
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
    found: list[tuple[MissionItem, Any]] = []
    for i, raw in enumerate(mission["items"]):
        where = f"mission.items[{i}]"
        kind = raw.get("type") if isinstance(raw, dict) else None
        if kind == "SimpleItem":
            one = _simple(raw, i, where, problems)
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
    if problems:
        raise ImportRejected(problems)
    vehicle = mission.get("vehicleType")
    speed = _num(
        mission.get(
            "hoverSpeed" if vehicle in MULTIROTOR_TYPES or vehicle is None else "cruiseSpeed"
        )
    )
    extras = {k: plan[k] for k in ("geoFence", "rallyPoints") if isinstance(plan.get(k), dict)}
    return Imported(
        items=items, home=home, speed_mps=speed if speed and speed > 0 else None, extras=extras
    )


def _complex(
    raw: dict[str, Any], i: int, where: str, problems: list[Problem]
) -> list[tuple[MissionItem, Any]]:
    kind = raw.get("complexItemType")
    # survey, corridor and structure scans keep their flattened items in TransectStyleComplexItem;
    # other styles (e.g. AgriculturalStyleComplexItem) in a section of their own, with the same key
    sections = [raw.get("TransectStyleComplexItem")] + [
        v for v in raw.values() if isinstance(v, dict)
    ]
    inner = next(
        (s["Items"] for s in sections if isinstance(s, dict) and isinstance(s.get("Items"), list)),
        None,
    )
    if not isinstance(inner, list) or not inner:
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
    for k, sub in enumerate(inner):
        one = _simple(sub, i, f"{where}.TransectStyleComplexItem.Items[{k}]", problems)
        if one:
            out.append(one)
    return out


def _resolve_jumps(
    found: list[tuple[MissionItem, Any]], problems: list[Problem]
) -> list[MissionItem]:
    """DO_JUMP targets are doJumpIds in a plan; ours are seq numbers (index + 1)."""
    seq_of = {jid: n + 1 for n, (_, jid) in enumerate(found) if _is_int(jid)}
    items = []
    for n, (item, _) in enumerate(found):
        if item.command == DO_JUMP and item.params[0] is not None:
            target = item.params[0]
            if target != int(target) or int(target) not in seq_of:
                problems.append(
                    Problem(
                        f"items[{n}].params[0]",
                        "DO_JUMP target is no item's doJumpId",
                        target,
                        index=n,
                        command=DO_JUMP,
                    )
                )
            else:
                p = item.params
                item = item.model_copy(
                    update={"params": (float(seq_of[int(target)]), p[1], p[2], p[3])}
                )
        items.append(item)
    return items


def _home(raw: Any, problems: list[Problem]) -> Home | None:
    if raw is None:
        return None
    values = [_num(v) for v in raw] if isinstance(raw, list) and len(raw) == 3 else None
    if values is None or values[0] is None or values[1] is None:
        problems.append(Problem("mission.plannedHomePosition", "must be [lat, lon, alt]", raw))
        return None
    return Home(values[0], values[1], values[2] or 0.0)


def export_plan(
    items: list[MissionItem],
    home: Home | None,
    speed_mps: float | None = None,
    extras: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Mission items -> a `.plan` document in QGroundControl's structure (ArduPilot, multirotor)."""
    extras = extras or {}
    out_items = []
    for n, item in enumerate(items):
        p = list(item.params)
        out: dict[str, Any] = {"AMSLAltAboveTerrain": None}
        if item.spec is not None and item.spec.positional:
            out |= {"Altitude": item.alt, "AltitudeMode": ALTITUDE_MODES.get(item.frame, 1)}
        out |= {
            "autoContinue": item.autocontinue,
            "command": item.command,
            "doJumpId": n + 1,
            "frame": item.frame,
            "params": [*p, item.lat, item.lon, item.alt],
            "type": "SimpleItem",
        }
        out_items.append(out)
    if home is not None:
        planned = [home.lat, home.lon, home.alt]
    else:
        first = next((i for i in items if i.spec and i.spec.positional), None)
        planned = [first.lat, first.lon, 0.0] if first else [0.0, 0.0, 0.0]
    return {
        "fileType": "Plan",
        "geoFence": extras.get("geoFence") or {"circles": [], "polygons": [], "version": 2},
        "groundStation": "QGroundControl",
        "mission": {
            "cruiseSpeed": DEFAULT_CRUISE_MPS,
            "firmwareType": FIRMWARE_ARDUPILOT,
            "globalPlanAltitudeMode": 1,
            "hoverSpeed": speed_mps or DEFAULT_HOVER_MPS,
            "items": out_items,
            "plannedHomePosition": planned,
            "vehicleType": VEHICLE_MULTIROTOR,
            "version": 2,
        },
        "rallyPoints": extras.get("rallyPoints") or {"points": [], "version": 2},
        "version": 1,
    }
