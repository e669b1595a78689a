"""QGroundControl altitude modes, read as QGroundControl means them, on plans shaped as it writes them.

Every item below has the keys QGroundControl's SimpleMissionItem::save writes (alphabetical, as
QJsonDocument orders them): `AMSLAltAboveTerrain`, `Altitude`, `AltitudeMode` on items with an
altitude, then `autoContinue`, `command`, `doJumpId` (its sequence number), `frame`, `params` (7,
NaN written as null) and `type`. Modes: 1 relative (frame 3), 2 AMSL (frame 0), 3 calculated above
terrain (frame 0, params[6] = terrain + Altitude, null until QGC's terrain query answered), 4
terrain frame (frame 10). Compare QGroundControl's test/plans/TerrainTest-ArduCopter.plan.
"""

from __future__ import annotations

import copy
import json
from typing import Any

import pytest

from server.missions.items import MissionItem
from server.missions.qgc import ImportRejected, parse_plan
from server.missions.qgc_export import export_plan
from server.missions.validate import Home, MissionLimits, validate_items

HOME = [47.397742, 8.545594, 488]  # plannedHomePosition: lat, lon, metres AMSL


def item(
    command: int,
    frame: int,
    params: list[Any],
    jump_id: int,
    mode: Any = None,
    altitude: Any = None,
    amsl_above_terrain: Any = None,
    auto: bool = True,
) -> dict[str, Any]:
    """One SimpleItem as QGroundControl saves it (altitude keys when `mode` is given)."""
    out: dict[str, Any] = {}
    if mode is not None:
        out = {
            "AMSLAltAboveTerrain": amsl_above_terrain,
            "Altitude": altitude,
            "AltitudeMode": mode,
        }
    return out | {
        "autoContinue": auto,
        "command": command,
        "doJumpId": jump_id,
        "frame": frame,
        "params": params,
        "type": "SimpleItem",
    }


def takeoff(jump_id: int = 1, alt: float = 20) -> dict[str, Any]:
    """NAV_TAKEOFF, relative (QGroundControl always writes take-off relative)."""
    return item(22, 3, [0, 0, 0, None, HOME[0], HOME[1], alt], jump_id, 1, alt)


def waypoint(jump_id: int, mode: int, frame: int, alt: Any, **keys: Any) -> dict[str, Any]:
    """NAV_WAYPOINT with yaw null (the autopilot's default), as QGroundControl writes it."""
    lat, lon = HOME[0] + jump_id * 2e-4, HOME[1] + 1e-4
    keys.setdefault("altitude", alt)
    return item(16, frame, [0, 0, 0, None, lat, lon, alt], jump_id, mode, **keys)


def plan(items: list[dict[str, Any]], **mission: Any) -> dict[str, Any]:
    """A whole .plan around `items`, with QGroundControl's mission keys."""
    return {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "groundStation": "QGroundControl",
        "mission": {
            "cruiseSpeed": 15,
            "firmwareType": 3,
            "globalPlanAltitudeMode": 0,
            "hoverSpeed": 5,
            "items": items,
            "plannedHomePosition": HOME,
            "vehicleType": 2,
            "version": 2,
        }
        | mission,
        "rallyPoints": {"points": [], "version": 2},
        "version": 1,
    }


def refusals(document: dict[str, Any]) -> list[dict[str, Any]]:
    """The problems an import names (it must refuse)."""
    with pytest.raises(ImportRejected) as err:
        parse_plan(copy.deepcopy(document))
    return [p.as_dict() for p in err.value.problems]


def round_trip(document: dict[str, Any]) -> dict[str, Any]:
    """Import, then export, through JSON as the server stores and serves it."""
    imported = parse_plan(copy.deepcopy(document))
    stored = json.loads(json.dumps(imported.extras))
    home = imported.home
    return json.loads(json.dumps(export_plan(imported.items, home, imported.speed_mps, stored)))


def test_mode_1_is_relative_to_home():
    imported = parse_plan(plan([takeoff(), waypoint(2, 1, 3, 35)]))
    wp = imported.items[1]
    assert (wp.frame, wp.alt, wp.params) == (3, 35, (0, 0, 0, None))
    assert validate_items(imported.items, MissionLimits(), imported.home) == []


def test_mode_2_amsl_is_kept_and_checked_against_the_planned_home():
    imported = parse_plan(plan([takeoff(), waypoint(2, 2, 0, 530)]))
    wp = imported.items[1]
    # flown as QGroundControl uploads it: frame 0, metres AMSL; the plan's home states the reference
    assert (wp.frame, wp.alt) == (0, 530) and imported.home == Home(*HOME)
    assert imported.extras["qgc"]["items"][1]["AltitudeMode"] == 2
    assert validate_items(imported.items, MissionLimits(), imported.home) == []  # 42 m above home
    high = parse_plan(plan([takeoff(), waypoint(2, 2, 0, 700)]))
    (problem,) = validate_items(high.items, MissionLimits(), high.home)
    assert problem.where == "items[1].alt" and problem.value == 212  # 700 - 488


def test_an_amsl_item_needs_the_planned_home_and_its_altitude():
    without = plan([takeoff(), waypoint(2, 2, 0, 530)])
    del without["mission"]["plannedHomePosition"]
    (problem,) = refusals(without)
    assert problem["index"] == 1 and problem["what"] == (
        "item 1: AltitudeMode 2 (AMSL) needs the plan's plannedHomePosition to be checked "
        "against home, and the plan has none"
    )
    terrain = plan([waypoint(2, 3, 0, 531.5, altitude=40, amsl_above_terrain=531.5)])
    del terrain["mission"]["plannedHomePosition"]
    assert "AltitudeMode 3 (terrain-calculated, AMSL)" in refusals(terrain)[0]["what"]
    # a relative plan does without (as before)
    assert parse_plan(plan([takeoff()], plannedHomePosition=None)).home is None
    # a null home altitude is never taken as 0 m
    null_alt = plan([takeoff(), waypoint(2, 1, 3, 30)], plannedHomePosition=[*HOME[:2], None])
    (problem,) = refusals(null_alt)
    assert problem["where"] == "mission.plannedHomePosition[2]" and "no altitude" in problem["what"]


def test_mode_3_resolved_flies_the_amsl_altitude_qgroundcontrol_computed():
    # 40 m above terrain where QGroundControl's terrain query answered 491.5 m: params[6] 531.5
    document = plan([takeoff(), waypoint(2, 3, 0, 531.5, altitude=40, amsl_above_terrain=531.5)])
    imported = parse_plan(document)
    wp = imported.items[1]
    assert (wp.frame, wp.alt) == (0, 531.5)
    kept = imported.extras["qgc"]["items"][1]
    assert (kept["AltitudeMode"], kept["Altitude"], kept["AMSLAltAboveTerrain"]) == (3, 40, 531.5)
    assert validate_items(imported.items, MissionLimits(), imported.home) == []


def test_mode_3_unresolved_is_refused_as_no_altitude_never_read_as_0():
    # QGroundControl writes params[6] null until its terrain query answers
    document = plan([takeoff(), waypoint(2, 3, 0, None, altitude=80)])
    (problem,) = refusals(document)
    assert problem == {
        "where": "mission.items[1].params[6]",
        "what": "item 1: no altitude (AltitudeMode 3, terrain-calculated, unresolved)",
        "value": None,
        "limit": None,
        "index": 1,
        "command": 16,
    }
    # a null altitude in any other mode is refused too, naming that mode
    (relative,) = refusals(plan([takeoff(), waypoint(2, 1, 3, None, altitude=30)]))
    assert relative["what"] == "item 1: no altitude (AltitudeMode 1, relative to home)"
    (bare,) = refusals(plan([takeoff(), item(16, 0, [0, 0, 0, None, 47.4, 8.5, None], 2)]))
    assert bare["what"] == "item 1: no altitude (frame 0 GLOBAL, AMSL)"


def survey(distance_mode: int, inner: list[dict[str, Any]]) -> dict[str, Any]:
    """A survey ComplexItem as QGroundControl saves it, flattened items and all."""
    return {
        "TransectStyleComplexItem": {
            "CameraCalc": {"DistanceMode": distance_mode, "DistanceToSurface": 40, "version": 2},
            "CameraShots": 0,
            "CameraTriggerInTurnAround": True,
            "HoverAndCapture": False,
            "Items": inner,
            "Refly90Degrees": False,
            "TurnAroundDistance": 10,
            "VisualTransectPoints": [],
            "version": 2,
        },
        "complexItemType": "survey",
        "polygon": [],
        "type": "ComplexItem",
        "version": 5,
    }


def test_a_terrain_following_survey_is_taken_when_resolved_and_refused_when_not():
    resolved = [
        item(16, 0, [0, 0, 0, None, 47.3981, 8.5460, 529.0], 2),
        item(16, 0, [0, 0, 0, None, 47.3985, 8.5460, 531.2], 3),
    ]
    imported = parse_plan(plan([takeoff(), survey(3, resolved)]))
    assert [(i.frame, i.alt) for i in imported.items[1:]] == [(0, 529.0), (0, 531.2)]
    unresolved = copy.deepcopy(resolved)
    unresolved[1]["params"][6] = None
    (problem,) = refusals(plan([takeoff(), survey(3, unresolved)]))
    assert problem["index"] == 1
    assert problem["where"] == "mission.items[1].TransectStyleComplexItem.Items[1].params[6]"
    assert problem["what"] == (
        "item 1 (complex item 'survey', flattened item 1): "
        "no altitude (DistanceMode 3, terrain-calculated, unresolved)"
    )


def test_mode_4_and_frame_10_are_refused_with_the_reason():
    document = plan([takeoff(), waypoint(2, 1, 3, 30), waypoint(3, 4, 10, 50)])
    (problem,) = refusals(document)
    assert problem["index"] == 2 and problem["command"] == 16 and problem["value"] == 4
    assert problem["where"] == "mission.items[2].AltitudeMode"
    assert problem["what"].startswith("item 2: AltitudeMode 4 (terrain frame")
    assert "Aerobase neither supplies nor checks" in problem["what"]
    # without the altitude keys QGroundControl reads the mode from the frame; so do we
    (bare,) = refusals(plan([takeoff(), item(16, 10, [0, 0, 0, None, 47.4, 8.5, 50], 2)]))
    assert bare["where"] == "mission.items[1].frame"
    assert bare["what"].startswith("item 1: frame 10 GLOBAL_TERRAIN_ALT (terrain frame")
    inner = [item(16, 10, [0, 0, 0, None, 47.3981, 8.5460, 40], 2)]
    (flattened,) = refusals(plan([takeoff(), survey(4, inner)]))
    assert flattened["index"] == 1 and "DistanceMode 4 (terrain frame)" in flattened["what"]


@pytest.mark.parametrize(
    ("change", "where", "words"),
    [
        ({"frame": 0}, ".frame", "AltitudeMode 1 (relative to home) is uploaded in frame 3"),
        ({"Altitude": 45}, ".Altitude", "Altitude 45 (AltitudeMode 1, relative to home) and"),
        ({"AltitudeMode": 0}, ".AltitudeMode", "AltitudeMode must be 1"),
        ({"AltitudeMode": 5}, ".AltitudeMode", "AltitudeMode must be 1"),
        ({"AltitudeMode": None}, ".AltitudeMode", "AltitudeMode must be 1"),
        ({"AltitudeMode": "1"}, ".AltitudeMode", "AltitudeMode must be 1"),
        ({"Altitude": "high"}, ".Altitude", "Altitude must be a number or null"),
        ({"AMSLAltAboveTerrain": [1]}, ".AMSLAltAboveTerrain", "must be a number or null"),
    ],
)
def test_a_plan_that_contradicts_itself_is_refused(change, where, words):
    wp = waypoint(2, 1, 3, 30) | change
    (problem,) = refusals(plan([takeoff(), wp]))
    assert problem["where"] == f"mission.items[1]{where}" and problem["index"] == 1
    assert problem["what"].startswith("item 1: ") and words in problem["what"]


def test_null_params_are_the_autopilots_default_and_null_positions_are_refused():
    imported = parse_plan(plan([takeoff(), waypoint(2, 1, 3, 30)]))
    assert imported.items[1].params[3] is None  # yaw: NaN on the wire, "use the default"
    no_position = waypoint(2, 1, 3, 30)
    no_position["params"][4] = None
    (problem,) = refusals(plan([takeoff(), no_position]))
    assert problem["what"] == "item 1: no position (latitude or longitude is null)"
    # take-off and land may leave their position to the vehicle (0, 0: where it is)
    up = item(22, 3, [0, 0, 0, None, None, None, 20], 1, 1, 20)
    down = item(21, 3, [0, 0, 0, None, None, None, 0], 2, 1, 0)
    assert [(i.lat, i.lon) for i in parse_plan(plan([up, down])).items] == [(0, 0), (0, 0)]


MIXED = plan(
    [
        takeoff(1, 25),
        waypoint(2, 1, 3, 30),
        item(178, 2, [1, 4.5, -1, 0, 0, 0, 0], 3),  # DO_CHANGE_SPEED: no altitude keys
        waypoint(4, 2, 0, 530.25, auto=False),
        waypoint(5, 3, 0, 531.5, altitude=40, amsl_above_terrain=531.5),
        item(177, 2, [2, 1, 0, 0, 0, 0, 0], 6),  # DO_JUMP to doJumpId 2, once
        item(201, 3, [0, 0, 0, 0, 47.3985, 8.5452, 0], 7, 1, 0),  # DO_SET_ROI
        item(21, 3, [0, 0, 0, None, HOME[0], HOME[1], 0], 8, 1, 0),
    ],
    cruiseSpeed=12,
    hoverSpeed=4.5,
    firmwareType=12,
)


def test_round_trip_gives_back_the_plan_qgroundcontrol_wrote():
    assert round_trip(MIXED) == MIXED
    imported = parse_plan(copy.deepcopy(MIXED))
    assert imported.items[3].autocontinue is False and imported.speed_mps == 4.5
    assert imported.items[5].params[0] == 2  # our seq of doJumpId 2


def test_round_trip_keeps_doJumpIds_that_are_not_sequence_numbers():
    renumbered = copy.deepcopy(MIXED)
    ids = [7, 9, 10, 11, 12, 14, 15, 16]
    for raw, jump_id in zip(renumbered["mission"]["items"], ids, strict=True):
        raw["doJumpId"] = jump_id
    renumbered["mission"]["items"][5]["params"][0] = 9
    imported = parse_plan(copy.deepcopy(renumbered))
    assert imported.items[5].params[0] == 2  # doJumpId 9 is our seq 2
    assert round_trip(renumbered) == renumbered
    twice = copy.deepcopy(renumbered)
    twice["mission"]["items"][2]["doJumpId"] = 9
    (problem,) = refusals(twice)
    assert "carried by 2 items" in problem["what"]


def test_a_changed_mission_exports_what_it_now_is():
    imported = parse_plan(copy.deepcopy(MIXED))
    items = list(imported.items)
    # the terrain-calculated waypoint moved up 10 m: no longer what QGroundControl computed
    items[4] = items[4].model_copy(update={"alt": 541.5})
    out = export_plan(items, imported.home, imported.speed_mps, imported.extras)["mission"]
    moved = out["items"][4]
    assert (moved["AltitudeMode"], moved["Altitude"], moved["AMSLAltAboveTerrain"]) == (
        2,
        541.5,
        None,
    )
    assert out["items"][3]["AltitudeMode"] == 2 and out["items"][1]["Altitude"] == 30
    # an item added: doJumpIds become sequence numbers again, DO_JUMP follows its target
    extra = MissionItem(command=16, frame=3, params=(0, 0, 0, None), lat=47.398, lon=8.546, alt=30)
    items.insert(1, extra)
    items[6] = items[6].model_copy(update={"params": (3.0, 1.0, 0.0, 0.0)})
    out = export_plan(items, imported.home, imported.speed_mps, imported.extras)["mission"]
    assert [i["doJumpId"] for i in out["items"]] == list(range(1, 10))
    assert out["items"][6]["params"][0] == 3


def test_speeds_and_vehicle_come_back_and_the_missions_speed_is_the_vehicles_own():
    plane = plan([takeoff(), waypoint(2, 1, 3, 60)], vehicleType=1, cruiseSpeed=18, hoverSpeed=5)
    imported = parse_plan(copy.deepcopy(plane))
    assert imported.speed_mps == 18  # a fixed wing flies its cruise speed
    out = export_plan(imported.items, imported.home, 20.0, imported.extras)["mission"]
    assert (out["vehicleType"], out["cruiseSpeed"], out["hoverSpeed"]) == (1, 20.0, 5)
    out = export_plan(imported.items, imported.home, None, imported.extras)["mission"]
    assert out["cruiseSpeed"] == 18
