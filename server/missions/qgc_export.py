"""Mission items to a QGroundControl `.plan` document, giving back what an import kept. Pure."""

from __future__ import annotations

from typing import Any

from server.missions.items import DO_JUMP, MissionItem
from server.missions.qgc import (
    DEFAULT_CRUISE_MPS,
    DEFAULT_HOVER_MPS,
    FIRMWARE_ARDUPILOT,
    KEPT_MISSION_KEYS,
    MULTIROTOR_TYPES,
    VEHICLE_MULTIROTOR,
    plan_number,
)
from server.missions.qgc_altitude import export_keys
from server.missions.validate import Home


def _kept_for(items: list[MissionItem], extras: dict[str, Any]) -> tuple[list[Any], list[int]]:
    """Per item: the altitude keys its import carried (None: derive them), and the doJumpIds.

    Altitude keys are used for an item still of the command, frame and altitude they were read
    with; the plan's doJumpIds while the mission still has the plan's commands in order and
    they are distinct (a stale or repeated id would send a DO_JUMP elsewhere): else seq numbers.
    """
    kept = extras.get("qgc")
    entries = kept.get("items") if isinstance(kept, dict) else None
    if not isinstance(entries, list) or len(entries) != len(items):
        entries = [None] * len(items)
    entries = [e if isinstance(e, dict) else None for e in entries]
    alts = [
        e
        if e is not None
        and (e.get("command"), e.get("frame"), e.get("alt")) == (i.command, i.frame, i.alt)
        else None
        for e, i in zip(entries, items, strict=True)
    ]
    kept_ids = [e.get("doJumpId") if e is not None else None for e in entries]
    same = all(
        e is not None and e.get("command") == i.command for e, i in zip(entries, items, strict=True)
    )
    ids = [j for j in kept_ids if isinstance(j, int) and not isinstance(j, bool)]
    if not same or len(ids) != len(items) or len(set(ids)) != len(ids):
        ids = [n + 1 for n in range(len(items))]
    return alts, ids


def export_plan(
    items: list[MissionItem],
    home: Home | None,
    speed_mps: float | None = None,
    extras: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Mission items -> a `.plan` document in QGroundControl's structure.

    An imported plan's firmware, vehicle, speeds, doJumpIds and altitude keys come back as they
    were (`extras["qgc"]`); otherwise ArduPilot, multirotor, seq numbers as doJumpIds.
    """
    extras = extras or {}
    alts, ids = _kept_for(items, extras)
    out_items = []
    for n, item in enumerate(items):
        p = list(item.params)
        if item.command == DO_JUMP and p[0] is not None and p[0] == int(p[0]):
            # our DO_JUMP target is a seq number; the plan's is the target's doJumpId
            if 1 <= p[0] <= len(items):
                p[0] = float(ids[int(p[0]) - 1])
        out: dict[str, Any] = {}
        if item.spec is not None and item.spec.positional:
            out |= export_keys(item.frame, item.alt, alts[n])
        out |= {
            "autoContinue": item.autocontinue,
            "command": item.command,
            "doJumpId": ids[n],
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
    kept: dict[str, Any] = extras["qgc"] if isinstance(extras.get("qgc"), dict) else {}
    mission = {k: kept[k] for k in KEPT_MISSION_KEYS if plan_number(kept.get(k)) is not None}
    vehicle = mission.get("vehicleType", VEHICLE_MULTIROTOR)
    speed_key = "hoverSpeed" if vehicle in MULTIROTOR_TYPES else "cruiseSpeed"
    mission = {
        "cruiseSpeed": DEFAULT_CRUISE_MPS,
        "firmwareType": FIRMWARE_ARDUPILOT,
        "globalPlanAltitudeMode": 1,
        "hoverSpeed": DEFAULT_HOVER_MPS,
        "vehicleType": VEHICLE_MULTIROTOR,
        **mission,
    }
    if speed_mps:
        mission[speed_key] = speed_mps
    return {
        "fileType": "Plan",
        "geoFence": extras.get("geoFence") or {"circles": [], "polygons": [], "version": 2},
        "groundStation": "QGroundControl",
        "mission": {
            **{k: mission[k] for k in ("cruiseSpeed", "firmwareType", "globalPlanAltitudeMode")},
            "hoverSpeed": mission["hoverSpeed"],
            "items": out_items,
            "plannedHomePosition": planned,
            "vehicleType": mission["vehicleType"],
            "version": 2,
        },
        "rallyPoints": extras.get("rallyPoints") or {"points": [], "version": 2},
        "version": 1,
    }
