"""Missions, pure file formats: QGroundControl .plan and QGC WPL 110, import, export, round trips."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from server.missions.items import COMMANDS, MissionItem
from server.missions.qgc import ImportRejected, parse_plan
from server.missions.qgc_export import export_plan
from server.missions.validate import Home
from server.missions.wpl import HEADER, export_wpl, parse_wpl

SHARED_FIXTURE = Path("/work/shared/fixtures/qgc/simple_square.plan")
# byte for byte the file QGroundControl wrote (../shared/fixtures/qgc/simple_square.plan), kept here
# so the suite does not depend on the shared folder being mounted
SIMPLE_SQUARE_PLAN = """{
    "fileType": "Plan",
    "geoFence": {
        "circles": [],
        "polygons": [],
        "version": 2
    },
    "groundStation": "QGroundControl",
    "mission": {
        "cruiseSpeed": 15,
        "firmwareType": 12,
        "globalPlanAltitudeMode": 1,
        "hoverSpeed": 5,
        "items": [
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 20,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 22,
                "doJumpId": 1,
                "frame": 3,
                "params": [0, 0, 0, null, 47.397742, 8.545594, 20],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 20,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 16,
                "doJumpId": 2,
                "frame": 3,
                "params": [0, 0, 0, null, 47.398742, 8.546594, 20],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 20,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 16,
                "doJumpId": 3,
                "frame": 3,
                "params": [0, 0, 0, null, 47.398742, 8.544594, 20],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 20,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 16,
                "doJumpId": 4,
                "frame": 3,
                "params": [0, 0, 0, null, 47.396742, 8.544594, 20],
                "type": "SimpleItem"
            },
            {
                "AMSLAltAboveTerrain": null,
                "Altitude": 20,
                "AltitudeMode": 1,
                "autoContinue": true,
                "command": 16,
                "doJumpId": 5,
                "frame": 3,
                "params": [0, 0, 0, null, 47.396742, 8.546594, 20],
                "type": "SimpleItem"
            }
        ],
        "plannedHomePosition": [47.397742, 8.545594, 488],
        "vehicleType": 2,
        "version": 2
    },
    "rallyPoints": {
        "points": [],
        "version": 2
    },
    "version": 1
}
"""


def plan_fixture() -> dict:
    """The .plan file QGroundControl wrote."""
    return json.loads(SIMPLE_SQUARE_PLAN)


def test_the_embedded_fixture_is_the_shared_file():
    if SHARED_FIXTURE.exists():
        assert json.loads(SHARED_FIXTURE.read_text()) == plan_fixture()


def simple(command: int, frame: int = 3, params=(0, 0, 0, None, 0, 0, 0), jump_id: int = 1) -> dict:
    """One QGC SimpleItem."""
    return {
        "type": "SimpleItem",
        "command": command,
        "frame": frame,
        "params": list(params),
        "autoContinue": True,
        "doJumpId": jump_id,
        "AMSLAltAboveTerrain": None,
    }


def wrap(items: list) -> dict:
    """A minimal .plan around some items."""
    return {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "QGroundControl",
        "mission": {"version": 2, "items": items, "plannedHomePosition": [47.0, 8.0, 400]},
    }


def test_the_qgroundcontrol_fixture_imports():
    imported = parse_plan(plan_fixture())
    assert [i.command for i in imported.items] == [22, 16, 16, 16, 16]
    assert all(i.frame == 3 and i.alt == 20 for i in imported.items)
    assert (imported.items[1].lat, imported.items[1].lon) == (47.398742, 8.546594)
    assert imported.items[0].params == (0, 0, 0, None)
    assert imported.home == Home(47.397742, 8.545594, 488)
    assert imported.speed_mps == 5  # hoverSpeed of a multirotor plan
    assert imported.extras["geoFence"]["version"] == 2


def test_export_carries_qgroundcontrols_structure():
    plan = export_plan(parse_plan(plan_fixture()).items, Home(47.397742, 8.545594, 488), 5.0)
    reference = plan_fixture()
    assert set(reference) <= set(plan)
    assert (
        plan["fileType"] == "Plan"
        and plan["version"] == 1
        and plan["groundStation"] == "QGroundControl"
    )
    mission = plan["mission"]
    assert set(reference["mission"]) <= set(mission)
    assert mission["version"] == 2 and mission["firmwareType"] == 3 and mission["vehicleType"] == 2
    assert mission["plannedHomePosition"] == [47.397742, 8.545594, 488]
    for ours, theirs in zip(mission["items"], reference["mission"]["items"], strict=True):
        assert set(theirs) == set(ours)
        for key in (
            "type",
            "command",
            "frame",
            "params",
            "autoContinue",
            "doJumpId",
            "AltitudeMode",
        ):
            assert ours[key] == theirs[key], key
    assert (
        plan["geoFence"] == reference["geoFence"]
        and plan["rallyPoints"] == reference["rallyPoints"]
    )


def test_non_positional_items_export_without_altitude_keys():
    plan = export_plan([MissionItem(command=178, frame=2, params=(1, 8, -1, 0))], None)
    item = plan["mission"]["items"][0]
    assert (
        "Altitude" not in item and item["params"] == [1, 8, -1, 0, 0, 0, 0] and item["frame"] == 2
    )


def test_unsupported_items_are_all_named_by_index_and_command():
    items = [
        simple(22, params=(0, 0, 0, None, 47, 8, 20)),
        simple(84, 2, (1, 1500, 0, 0, 0, 0, 0)),
        simple(16, 3, (0, 0, 0, None, 47, 8, 20)),
        simple(30, 2),
        simple(16, 1),
        {"type": "Weird"},
        simple(16, 3, (0, 0, 0)),
    ]
    with pytest.raises(ImportRejected) as err:
        parse_plan(wrap(items))
    named = [(p.index, p.command) for p in err.value.problems]
    assert named == [(1, 84), (3, 30), (4, 16), (5, None), (6, 16)]
    assert (
        "NAV_VTOL_TAKEOFF" in err.value.problems[0].what
        and "NAV_CONTINUE_AND_CHANGE_ALT" in err.value.problems[1].what
    )


def test_complex_items_import_their_flattened_items_or_are_named():
    inner = [
        simple(16, 3, (0, 0, 0, None, 47.001, 8.001, 50), 2),
        simple(206, 2, (12.5, 0, 1, 0, 0, 0, 0), 3),
        simple(16, 3, (0, 0, 0, None, 47.002, 8.001, 50), 4),
        simple(206, 2, (0, 0, 0, 0, 0, 0, 0), 5),
    ]
    survey = {
        "type": "ComplexItem",
        "complexItemType": "survey",
        "version": 5,
        "TransectStyleComplexItem": {"Items": inner, "version": 1},
        "polygon": [[47, 8]],
    }
    plan = wrap([simple(22, 3, (0, 0, 0, None, 47, 8, 50), 1), survey, simple(20, 2, (0,) * 7, 6)])
    imported = parse_plan(plan)
    assert [i.command for i in imported.items] == [22, 16, 206, 16, 206, 20]
    assert imported.items[2].params[0] == 12.5
    agri = {
        "type": "ComplexItem",
        "complexItemType": "AgriculturalStyle",
        "AgriculturalStyleComplexItem": {"Items": inner[:1], "visualTransectPoints": []},
    }
    again = parse_plan(wrap([simple(22, 3, (0, 0, 0, None, 47, 8, 50), 1), agri]))
    assert [i.command for i in again.items] == [22, 16]
    bare = {"type": "ComplexItem", "complexItemType": "CorridorScan", "polyline": []}
    with pytest.raises(ImportRejected) as err:
        parse_plan(wrap([simple(22, 3, (0, 0, 0, None, 47, 8, 50)), bare]))
    (problem,) = err.value.problems
    assert problem.index == 1 and "CorridorScan" in problem.what


def test_do_jump_targets_are_mapped_from_jump_ids_to_sequence_numbers():
    items = [
        simple(22, 3, (0, 0, 0, None, 47, 8, 20), 7),
        simple(16, 3, (0, 0, 0, None, 47.1, 8, 20), 9),
        simple(177, 2, (9, 3, 0, 0, 0, 0, 0), 10),
    ]
    imported = parse_plan(wrap(items))
    assert imported.items[2].params[:2] == (2.0, 3)  # doJumpId 9 is our seq 2 (index 1)
    with pytest.raises(ImportRejected):
        parse_plan(wrap([*items[:2], simple(177, 2, (42, 1, 0, 0, 0, 0, 0), 10)]))


def every_supported_item(frames: tuple[int, ...]) -> list[MissionItem]:
    """One item of each supported command, positional ones in the given frames in turn."""
    items = [MissionItem(command=22, frame=3, params=(0, 0, 0, None), lat=47.1, lon=8.2, alt=15)]
    for n, cmd in enumerate(sorted(COMMANDS)):
        spec = COMMANDS[cmd]
        frame = frames[n % len(frames)]
        if cmd == 177:
            items.append(MissionItem(command=cmd, frame=2, params=(1, 2, 0, 0)))
        elif spec.positional:
            items.append(
                MissionItem(
                    command=cmd,
                    frame=frame,
                    params=(1.5, None, -2, 0.25),
                    lat=47.1 + n * 1e-4,
                    lon=8.2 - n * 1e-4,
                    alt=30 + n,
                    autocontinue=n % 2 == 0,
                )
            )
        else:
            items.append(MissionItem(command=cmd, frame=2, params=(1, 7.5, -1, 0)))
    return items


def test_qgc_round_trip_keeps_every_supported_item():
    items = every_supported_item((0, 3))
    again = parse_plan(json.loads(json.dumps(export_plan(items, Home(47.1, 8.2, 410.5), 6.5))))
    assert again.items == items and again.home == Home(47.1, 8.2, 410.5) and again.speed_mps == 6.5
    # a terrain-frame item (made through the API) exports as QGroundControl writes it, and is
    # refused on the way back in, by name, like any plan holding one
    terrain = every_supported_item((10, 0, 3))
    with pytest.raises(ImportRejected) as err:
        parse_plan(json.loads(json.dumps(export_plan(terrain, Home(47.1, 8.2, 410.5)))))
    refused = [p for p in err.value.problems if "terrain frame" in p.what]
    assert refused and len(refused) == len(err.value.problems)
    assert all(p.where.endswith(".AltitudeMode") and p.value == 4 for p in refused)


def test_wpl_round_trip_keeps_every_supported_item():
    items = every_supported_item((10, 0, 3))
    wpl = parse_wpl(export_wpl(items, Home(47.1, 8.2, 410.5)))
    assert wpl.items == items and wpl.home == Home(47.1, 8.2, 410.5)


def test_int_frames_are_stored_as_their_plain_numbers():
    plan = wrap(
        [
            simple(16, 6, (0, 0, 0, None, 47, 8, 20)),
            simple(16, 5, (0, 0, 0, None, 47, 8, 420)),
            simple(178, 11, (1, 5, -1, 0, 0, 0, 0)),
        ]
    )
    assert [i.frame for i in parse_plan(plan).items] == [3, 0, 10]
    with pytest.raises(ImportRejected) as err:
        parse_plan(wrap([simple(16, 11, (0, 0, 0, None, 47, 8, 30))]))
    assert "frame 10 GLOBAL_TERRAIN_ALT" in err.value.problems[0].what


def test_wpl_import_as_mission_planner_writes_it():
    text = (
        f"{HEADER}\r\n"
        "0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1\r\n"
        "1\t0\t3\t22\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t20.000000\t1\r\n"
        "2\t0\t3\t16\t0\t0\t0\tnan\t47.398742\t8.546594\t20\t1\r\n"
        "3\t0\t6\t82\t0\t0\t0\t0\t47.398742\t8.544594\t25\t1\r\n"
        "4\t0\t2\t178\t1\t8\t-1\t0\t0\t0\t0\t1\r\n"
        "5\t0\t3\t21\t0\t0\t0\t0\t47.397742\t8.545594\t0\t1\r\n"
    )
    imported = parse_wpl(text)
    assert imported.home == Home(47.397742, 8.545594, 488)
    assert [(i.command, i.frame) for i in imported.items] == [
        (22, 3),
        (16, 3),
        (82, 3),
        (178, 2),
        (21, 3),
    ]
    assert imported.items[1].params == (0, 0, 0, None)


def test_wpl_names_every_line_it_cannot_take():
    text = "\n".join(
        [
            HEADER,
            "0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t400\t1",
            "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t20\t1",
            "2\t0\t2\t84\t1\t1500\t0\t0\t0\t0\t0\t1",
            "3\t0\t3\t16\t0\t0\t0",
            "4\t0\t3\t16\t0\t0\t0\t0\tabc\t8\t20\t1",
            "7\t0\t3\t16\t0\t0\t0\t0\t47\t8\t20\t1",
            "6\t0\t3\t85\t0\t0\t0\t0\t0\t0\t0\t1",
        ]
    )
    with pytest.raises(ImportRejected) as err:
        parse_wpl(text)
    assert [(p.where, p.index, p.command) for p in err.value.problems] == [
        ("line 4", 1, 84),
        ("line 5", 2, None),
        ("line 6", 3, None),
        ("line 7", 4, None),
        ("line 8", 5, 85),
    ]
    with pytest.raises(ImportRejected):
        parse_wpl("QGC WPL 100\n")
    with pytest.raises(ImportRejected):
        parse_wpl("")
