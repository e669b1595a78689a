"""Missions over the live server: CRUD, roles, organisations, surveys, validation, import and export."""

from __future__ import annotations

import json
import math

from tests.conftest import Tenant
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN
from tests.server.test_missions_qgc_altitude import (
    MIXED,
    item,
    plan,
    survey,
    takeoff,
    waypoint,
)

LAT0, LON0 = 47.3977, 8.5456
DLAT = 200 / 111_195.0
DLON = 200 / (111_195.0 * math.cos(math.radians(LAT0)))
SQUARE = [
    [LON0, LAT0],
    [LON0 + DLON, LAT0],
    [LON0 + DLON, LAT0 + DLAT],
    [LON0, LAT0 + DLAT],
    [LON0, LAT0],
]
HOME = {"lat": LAT0, "lon": LON0, "alt": 488.0}


def waypoints(n: int = 3, alt: float = 20) -> list[dict]:
    """A takeoff, `n` waypoints and a landing."""
    items = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": LAT0, "lon": LON0, "alt": alt}
    ]
    for k in range(n):
        items.append(
            {
                "command": 16,
                "frame": 3,
                "params": [0, 0, 0, None],
                "lat": LAT0 + k * 1e-4,
                "lon": LON0 + 1e-4,
                "alt": alt,
                "autocontinue": True,
            }
        )
    items.append({"command": 21, "frame": 3, "lat": LAT0, "lon": LON0, "alt": 0})
    return items


def survey_body(**extra) -> dict:
    """A survey of a 200 m square with a 1-inch camera at 50 m."""
    survey = {
        "polygon": {"type": "Polygon", "coordinates": [SQUARE]},
        "camera": {
            "sensor_width_mm": 13.2,
            "sensor_height_mm": 8.8,
            "focal_length_mm": 8.8,
            "image_width_px": 5472,
            "image_height_px": 3648,
        },
        "front_overlap_pct": 70,
        "side_overlap_pct": 60,
        "altitude_m": 50,
        "speed_mps": 6,
        "heading_deg": 0,
        **extra,
    }
    return {"name": "survey", "kind": "survey", "survey": survey, "home": HOME}


def test_waypoint_mission_crud(api, tenant: Tenant):
    r = api.post(
        "/api/v1/missions",
        json={
            "name": "patrol",
            "description": "north fence",
            "items": waypoints(),
            "home": HOME,
            "speed_mps": 7,
        },
        headers=tenant.h("operator"),
    )
    assert r.status_code == 201, r.text
    mission = r.json()
    assert (
        mission["kind"] == "waypoints" and mission["source"] == "api" and mission["speed_mps"] == 7
    )
    first = mission["items"][0]
    assert first == {
        "command": 22,
        "frame": 3,
        "params": [0.0, 0.0, 0.0, None],
        "lat": LAT0,
        "lon": LON0,
        "alt": 20.0,
        "autocontinue": True,
    }
    assert mission["estimate"]["distance_m"] > 40 and mission["estimate"]["flight_time_s"] > 0
    listed = api.get("/api/v1/missions", headers=tenant.h("viewer")).json()
    assert [m["id"] for m in listed] == [mission["id"]]
    got = api.get(f"/api/v1/missions/{mission['id']}", headers=tenant.h("viewer")).json()
    assert got["items"] == mission["items"]
    r = api.patch(
        f"/api/v1/missions/{mission['id']}",
        json={"name": "patrol 2", "items": waypoints(5, 30)},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 200 and r.json()["name"] == "patrol 2" and len(r.json()["items"]) == 7
    assert r.json()["home"] == HOME and r.json()["description"] == "north fence"
    assert (
        api.delete(f"/api/v1/missions/{mission['id']}", headers=tenant.h("operator")).status_code
        == 204
    )
    assert (
        api.get(f"/api/v1/missions/{mission['id']}", headers=tenant.h("viewer")).status_code == 404
    )


def test_roles_and_organisations(api, tenant: Tenant, superuser_email):
    body = {"name": "m", "items": waypoints()}
    r = api.post("/api/v1/missions", json=body, headers=tenant.h("viewer"))
    assert r.status_code == 403
    mission = api.post("/api/v1/missions", json=body, headers=tenant.h("operator")).json()
    other = Tenant(api, superuser_email, "other")
    for method, path in (
        ("GET", ""),
        ("PATCH", ""),
        ("DELETE", ""),
        ("GET", "/export"),
        ("POST", "/validate"),
    ):
        r = api.request(
            method,
            f"/api/v1/missions/{mission['id']}{path}",
            json={} if method != "GET" else None,
            headers=other.h("admin"),
        )
        assert r.status_code == 404, (method, path, r.text)
    assert api.get("/api/v1/missions", headers=other.h("admin")).json() == []


def test_validation_errors_list_every_problem(api, tenant: Tenant):
    items = waypoints()
    items[1]["alt"] = 150
    items[2]["lat"] = 95
    items[3] = {"command": 84, "frame": 2, "params": [1, 1500, 0, 0]}
    r = api.post(
        "/api/v1/missions", json={"name": "bad", "items": items}, headers=tenant.h("operator")
    )
    assert r.status_code == 422
    error = r.json()["error"]
    assert error["code"] == "invalid_mission"
    assert [(d["where"], d["value"], d["limit"]) for d in error["details"]] == [
        ("items[1].alt", 150, 120),
        ("items[2].lat", 95, [-90, 90]),
        ("items[3].command", 84, error["details"][2]["limit"]),
    ]
    assert error["details"][2]["index"] == 3 and error["details"][2]["command"] == 84
    empty = api.post(
        "/api/v1/missions", json={"name": "empty", "items": []}, headers=tenant.h("operator")
    )
    assert empty.status_code == 422 and empty.json()["error"]["details"][0]["where"] == "items"


def test_survey_is_compiled_into_a_lawnmower(api, tenant: Tenant):
    r = api.post("/api/v1/missions", json=survey_body(), headers=tenant.h("operator"))
    assert r.status_code == 201, r.text
    mission = r.json()
    plan = mission["survey_plan"]
    assert (
        plan["line_count"] == 7
        and plan["line_spacing_m"] == 30
        and plan["trigger_distance_m"] == 15
    )
    assert plan["footprint_width_m"] == 75 and abs(plan["area_m2"] - 40_000) < 400
    commands = [i["command"] for i in mission["items"]]
    assert commands == [22, 178] + [16, 206, 16, 206] * 7 + [20]
    assert (
        mission["items"][0]["lat"] == LAT0 and mission["items"][0]["lon"] == LON0
    )  # takeoff at home
    assert mission["survey"]["polygon"]["coordinates"] == [SQUARE]
    # a change of the overlap compiles it again
    r = api.patch(
        f"/api/v1/missions/{mission['id']}",
        json={"survey": survey_body(side_overlap_pct=20)["survey"]},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 200 and r.json()["survey_plan"]["line_count"] == 4  # ceil(200 / 60)
    # waypoints only, without camera trigger items
    r = api.post(
        "/api/v1/missions", json=survey_body(camera_trigger=False), headers=tenant.h("operator")
    )
    assert [i["command"] for i in r.json()["items"]] == [22, 178] + [16, 16] * 7 + [20]
    # a footprint given directly
    r = api.post(
        "/api/v1/missions",
        json=survey_body(camera=None, footprint={"width_m": 50, "height_m": 40}),
        headers=tenant.h("operator"),
    )
    assert r.status_code == 201 and r.json()["survey_plan"]["line_spacing_m"] == 20


def test_survey_geometry_errors(api, tenant: Tenant):
    bowtie = [SQUARE[0], SQUARE[2], SQUARE[1], SQUARE[3], SQUARE[0]]
    cases = {
        "the polygon is empty": [],
        "a polygon needs at least 3 distinct points": [SQUARE[0], SQUARE[1], SQUARE[0]],
        "the polygon intersects itself": bowtie,
        "the area is too large": [
            [LON0, LAT0],
            [LON0 + 0.05, LAT0],
            [LON0 + 0.05, LAT0 + 0.05],
            [LON0, LAT0 + 0.05],
        ],
    }
    for what, ring in cases.items():
        body = survey_body()
        body["survey"]["polygon"]["coordinates"] = [ring]
        r = api.post("/api/v1/missions", json=body, headers=tenant.h("operator"))
        assert r.status_code == 422, (what, r.text)
        assert r.json()["error"]["details"][0]["what"].startswith(what), r.json()
    body = survey_body()
    body["survey"]["polygon"]["coordinates"] = [
        [[LON0 + 1e-3 * math.cos(k / 160), LAT0 + 1e-3 * math.sin(k / 160)] for k in range(1001)]
    ]
    r = api.post("/api/v1/missions", json=body, headers=tenant.h("operator"))
    assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error"
    r = api.post("/api/v1/missions", json=survey_body(altitude_m=300), headers=tenant.h("operator"))
    assert r.status_code == 422 and r.json()["error"]["details"][0]["where"] == "survey.altitude_m"
    r = api.post(
        "/api/v1/missions", json={"name": "s", "kind": "survey"}, headers=tenant.h("operator")
    )
    assert r.status_code == 422 and r.json()["error"]["details"][0]["where"] == "survey"


def test_validate_against_the_uavs_endurance(api, tenant: Tenant):
    mission = api.post("/api/v1/missions", json=survey_body(), headers=tenant.h("operator")).json()
    strong = tenant.create_asset("uav", attributes={"endurance_s": 1800, "cruise_speed_mps": 10})
    weak = tenant.create_asset("uav", attributes={"endurance_s": 120})
    default = tenant.create_asset("uav")
    url = f"/api/v1/missions/{mission['id']}/validate"
    ok = api.post(url, json={"uav_id": strong["id"]}, headers=tenant.h("operator")).json()
    assert ok["valid"] is True and ok["problems"] == []
    assert ok["uav"]["usable_endurance_s"] == 1440 and ok["estimate"]["distance_m"] > 1400
    bad = api.post(url, json={"uav_id": weak["id"]}, headers=tenant.h("operator")).json()
    assert bad["valid"] is False
    (problem,) = bad["problems"]
    assert problem["where"] == "mission" and problem["limit"] == 96 and problem["value"] > 96
    assert (
        api.post(url, json={"uav_id": default["id"]}, headers=tenant.h("operator")).json()["uav"][
            "endurance_s"
        ]
        == 1200
    )
    short = tenant.create_asset("uav", attributes={"max_range_m": 1000, "cruise_speed_mps": "fast"})
    report = api.post(url, json={"uav_id": short["id"]}, headers=tenant.h("operator")).json()
    assert [(p["where"], p["limit"]) for p in report["problems"]] == [
        ("uav.attributes.cruise_speed_mps", None),
        ("mission", 800),
    ]
    assert report["uav"]["cruise_speed_mps"] == 8
    base = tenant.create_asset("landing_base")
    r = api.post(url, json={"uav_id": base["id"]}, headers=tenant.h("operator"))
    assert r.status_code == 422 and r.json()["error"]["code"] == "not_a_uav"
    assert api.post(url, json={}, headers=tenant.h("operator")).json()["uav"] is None


def test_import_the_qgroundcontrol_fixture_and_export_it_back(api, tenant: Tenant):
    r = api.post(
        "/api/v1/missions/import?name=square",
        content=SIMPLE_SQUARE_PLAN,
        headers={**tenant.h("operator"), "Content-Type": "application/json"},
    )
    assert r.status_code == 201, r.text
    mission = r.json()
    assert mission["name"] == "square" and mission["source"] == "qgc" and len(mission["items"]) == 5
    assert mission["home"] == {"lat": 47.397742, "lon": 8.545594, "alt": 488}
    r = api.get(f"/api/v1/missions/{mission['id']}/export?format=qgc", headers=tenant.h("viewer"))
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/json")
    assert 'filename="square.plan"' in r.headers["content-disposition"]
    plan = r.json()
    reference = json.loads(SIMPLE_SQUARE_PLAN)
    assert set(plan) == set(reference) and set(plan["mission"]) == set(reference["mission"])
    assert plan["fileType"] == "Plan" and plan["mission"]["plannedHomePosition"] == [
        47.397742,
        8.545594,
        488,
    ]
    for ours, theirs in zip(plan["mission"]["items"], reference["mission"]["items"], strict=True):
        assert {k: ours[k] for k in ("command", "frame", "params")} == {
            k: theirs[k] for k in ("command", "frame", "params")
        }
    # the plan QGroundControl wrote comes back as it was: doJumpIds, altitude keys, speeds,
    # firmware (12, PX4) and the null yaw included
    assert plan == reference
    # our export imports again to the same items
    again = api.post(
        "/api/v1/missions/import",
        content=r.content,
        headers={**tenant.h("operator"), "Content-Type": "application/json"},
    ).json()
    assert again["items"] == mission["items"] and again["home"] == mission["home"]


def test_wpl_import_export_round_trip(api, tenant: Tenant):
    mission = api.post(
        "/api/v1/missions",
        json={"name": "w p/l", "items": waypoints(), "home": HOME},
        headers=tenant.h("operator"),
    ).json()
    r = api.get(
        f"/api/v1/missions/{mission['id']}/export",
        params={"format": "wpl"},
        headers=tenant.h("viewer"),
    )
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    assert 'filename="w_p_l.waypoints"' in r.headers["content-disposition"]
    lines = r.text.splitlines()
    assert lines[0] == "QGC WPL 110" and lines[1].split("\t")[:4] == ["0", "1", "0", "16"]
    assert len(lines) == 2 + len(mission["items"])
    for content_type in ("text/plain; charset=utf-8", "application/vnd.mavlink.wpl"):
        r2 = api.post(
            "/api/v1/missions/import",
            content=r.text,
            headers={**tenant.h("operator"), "Content-Type": content_type},
        )
        assert r2.status_code == 201, r2.text
        assert r2.json()["items"] == mission["items"] and r2.json()["home"] == HOME
        assert r2.json()["source"] == "wpl"


def test_import_refusals_name_every_item(api, tenant: Tenant):
    plan = json.loads(SIMPLE_SQUARE_PLAN)
    plan["mission"]["items"][2]["command"] = 84
    plan["mission"]["items"][4] = {"type": "ComplexItem", "complexItemType": "StructureScan"}
    r = api.post("/api/v1/missions/import", json=plan, headers=tenant.h("operator"))
    assert r.status_code == 422
    error = r.json()["error"]
    assert error["code"] == "import_rejected"
    assert [(d.get("index"), d.get("command")) for d in error["details"]] == [(2, 84), (4, None)]
    wpl = (
        "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t400\t1\n1\t0\t2\t84\t1\t1\t0\t0\t0\t0\t0\t1\n"
    )
    r = api.post(
        "/api/v1/missions/import",
        content=wpl,
        headers={**tenant.h("operator"), "Content-Type": "text/plain"},
    )
    assert r.status_code == 422 and r.json()["error"]["details"][0]["command"] == 84
    # an imported plan is validated like any mission (here: above the altitude limit)
    high = json.loads(SIMPLE_SQUARE_PLAN)
    high["mission"]["items"][1]["params"][6] = high["mission"]["items"][1]["Altitude"] = 500
    r = api.post("/api/v1/missions/import", json=high, headers=tenant.h("operator"))
    assert r.status_code == 422 and r.json()["error"]["details"][0]["where"] == "items[1].alt"
    for content, ctype, status in (
        (b"{not json", "application/json", 422),
        (b"\xff\xfe", "text/plain", 422),
        (b"hello", "image/png", 415),
        (b"x" * (5 * 1024 * 1024 + 1), "text/plain", 413),
    ):
        r = api.post(
            "/api/v1/missions/import",
            content=content,
            headers={**tenant.h("operator"), "Content-Type": ctype},
        )
        assert r.status_code == status, (ctype, r.text)
    assert (
        api.post("/api/v1/missions/import", json=plan, headers=tenant.h("viewer")).status_code
        == 403
    )


def test_qgroundcontrol_altitude_modes_over_http(api, tenant: Tenant):
    headers = tenant.h("operator")
    r = api.post("/api/v1/missions/import?name=mixed", json=MIXED, headers=headers)
    assert r.status_code == 201, r.text
    mission = r.json()
    assert [(i["frame"], i["alt"]) for i in mission["items"][3:5]] == [(0, 530.25), (0, 531.5)]
    assert mission["home"]["alt"] == 488 and mission["speed_mps"] == 4.5
    assert mission["extras"]["qgc"]["items"][4]["AltitudeMode"] == 3
    r = api.get(f"/api/v1/missions/{mission['id']}/export", headers=tenant.h("viewer"))
    assert r.status_code == 200 and r.json() == MIXED
    # terrain modes the server cannot take: 422 naming each item and its mode, never a 5xx
    refused = plan(
        [
            takeoff(),
            waypoint(2, 3, 0, None, altitude=80),
            waypoint(3, 4, 10, 50),
            survey(1, [item(16, 0, [0, 0, 0, None, 47.3981, 8.546, None], 4)]),
        ]
    )
    r = api.post("/api/v1/missions/import", json=refused, headers=headers)
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "import_rejected"
    assert error["message"] == (
        "mission.items[1].params[6]: item 1: no altitude "
        "(AltitudeMode 3, terrain-calculated, unresolved) (and 2 more)"
    )
    assert [(d["index"], d["command"]) for d in error["details"]] == [(1, 16), (2, 16), (3, 16)]
    assert "AltitudeMode 4 (terrain frame" in error["details"][1]["what"]
    assert error["details"][2]["what"] == (
        "item 3 (complex item 'survey', flattened item 0): no altitude (frame 0 GLOBAL, AMSL)"
    )


def test_a_mission_used_by_a_run_cannot_be_deleted(api, tenant: Tenant):
    mission = api.post(
        "/api/v1/missions",
        json={"name": "used", "items": waypoints()},
        headers=tenant.h("operator"),
    ).json()
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    r = api.post(
        "/api/v1/runs",
        json={"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 201, r.text
    r = api.delete(f"/api/v1/missions/{mission['id']}", headers=tenant.h("operator"))
    assert r.status_code == 409 and r.json()["error"]["code"] == "mission_in_use"
    assert (
        api.get(f"/api/v1/missions/{mission['id']}", headers=tenant.h("viewer")).status_code == 200
    )
