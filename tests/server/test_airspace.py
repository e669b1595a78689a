"""Airspace zones over the live server, and missions checked against them by their path."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta

from tests.conftest import Tenant, wait_for

LAT0, LON0 = 47.3977, 8.5456
M_LAT = 1 / 111_195.0
M_LON = 1 / (111_195.0 * math.cos(math.radians(LAT0)))
HOME = {"lat": LAT0, "lon": LON0, "alt": 488.0}


def at(east: float, north: float) -> list[float]:
    """[lon, lat] of a point `east`, `north` metres from home."""
    return [LON0 + east * M_LON, LAT0 + north * M_LAT]


def ring(*corners: tuple[float, float]) -> dict:
    """A GeoJSON Polygon of (east, north) corners in metres from home."""
    pts = [at(e, n) for e, n in corners]
    return {"type": "Polygon", "coordinates": [[*pts, pts[0]]]}


def wp(east: float, north: float, alt: float = 30, command: int = 16) -> dict:
    lon, lat = at(east, north)
    return {"command": command, "frame": 3, "lat": lat, "lon": lon, "alt": alt}


def mission(api, tenant: Tenant, items: list[dict], **extra) -> dict:  # type: ignore[no-untyped-def]
    r = api.post(
        "/api/v1/missions",
        json={"name": "m", "items": items, "home": HOME, **extra},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 201, r.text
    return dict(r.json())


def zone(api, tenant: Tenant, **body) -> dict:  # type: ignore[no-untyped-def]
    r = api.post("/api/v1/airspace/zones", json=body, headers=tenant.h("operator"))
    assert r.status_code == 201, r.text
    return dict(r.json())


def validate(api, tenant: Tenant, mission_id: str, **body) -> dict:  # type: ignore[no-untyped-def]
    r = api.post(f"/api/v1/missions/{mission_id}/validate", json=body, headers=tenant.h("operator"))
    assert r.status_code == 200, r.text
    return dict(r.json())


# the hospital: a 60 x 60 m square between two waypoints 200 m apart, neither inside it
HOSPITAL = ring((70, -30), (130, -30), (130, 30), (70, 30))
CROSSING = [wp(0, 0, 30, 22), wp(0, 0), wp(200, 0), wp(200, 100), {"command": 20, "frame": 2}]


def test_a_path_crossing_an_exclusion_zone_between_two_outside_waypoints_is_refused(
    api, tenant: Tenant
):
    m = mission(api, tenant, CROSSING)
    assert validate(api, tenant, m["id"])["valid"] is True
    hospital = zone(api, tenant, name="hospital", kind="exclusion", geometry=HOSPITAL)
    report = validate(api, tenant, m["id"])
    assert report["valid"] is False
    (problem,) = [p for p in report["problems"] if p.get("code") == "airspace"]
    assert problem["segment"] == ["items[1]", "items[2]"]
    assert problem["zone"]["id"] == hospital["id"] and problem["zone"]["name"] == "hospital"
    assert problem["value"] == 60.0  # metres of the segment inside the zone
    assert "items[1]→items[2]" in problem["what"] and "'hospital'" in problem["what"]
    # a run of it is refused the same way, before anything moves
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    ids = {"mission_id": m["id"], "uav_id": uav["id"], "base_id": base["id"]}
    r = api.post("/api/v1/runs", json=ids, headers=tenant.h("operator"))
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "airspace" and error["details"][0]["segment"] == [
        "items[1]",
        "items[2]",
    ]
    # above the zone's ceiling the same path is allowed
    api.patch(
        f"/api/v1/airspace/zones/{hospital['id']}",
        json={"ceiling_m": 25},
        headers=tenant.h("operator"),
    ).raise_for_status()
    assert validate(api, tenant, m["id"])["valid"] is True


def test_the_return_leg_to_the_base_is_checked(api, tenant: Tenant):
    # out east, then north, no RTL: the UAV flies straight back to the base across the zone
    items = [wp(0, 0, 30, 22), wp(0, 200), wp(200, 200)]
    m = mission(api, tenant, items)
    zone(
        api,
        tenant,
        name="school",
        kind="exclusion",
        geometry=ring((90, 90), (110, 90), (110, 110), (90, 110)),
    )
    (problem,) = [p for p in validate(api, tenant, m["id"])["problems"] if "segment" in p]
    assert problem["segment"] == ["items[2]", "home"] and "return leg" in problem["what"]


def test_a_survey_whose_lanes_clip_the_operating_area_is_refused(api, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    survey = {
        "polygon": ring((0, 0), (200, 0), (200, 200), (0, 200)),
        "footprint": {"width_m": 40, "height_m": 30},
        "side_overlap_pct": 0,
        "altitude_m": 50,
        "heading_deg": 0,
    }
    r = api.post(
        "/api/v1/missions",
        json={"name": "s", "kind": "survey", "survey": survey, "home": HOME},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 201, r.text
    m = r.json()
    # the operating area holds every waypoint of the lanes (their ends on the south and north
    # edges) but a notch cut in from the east reaches across the middle of the eastern lanes
    area = ring((-50, -50), (250, -50), (250, 90), (120, 100), (250, 110), (250, 250), (-50, 250))
    op = zone(
        api, tenant, name="operating area", kind="inclusion", geometry=area, base_id=base["id"]
    )
    assert op["ceiling_m"] == 120.0  # a base's operating area: 120 m above the base by default
    report = validate(api, tenant, m["id"], base_id=base["id"])
    clipped = [p for p in report["problems"] if p.get("code") == "airspace"]
    assert report["valid"] is False and clipped
    assert all(p["zone"]["id"] == op["id"] and "leaves inclusion" in p["what"] for p in clipped)
    lanes = {tuple(p["segment"]) for p in clipped}
    assert all(a.startswith("items[") and b.startswith("items[") for a, b in lanes)
    assert all(0 < p["value"] < 30 for p in clipped)  # the notch is at most 20 m wide
    # without the base, its operating area does not apply
    assert not [p for p in validate(api, tenant, m["id"])["problems"] if "segment" in p]


def test_the_operating_area_ceiling_is_enforced(api, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    zone(
        api,
        tenant,
        name="area",
        kind="inclusion",
        geometry={"type": "Point", "coordinates": at(0, 0)},
        radius_m=500,
        base_id=base["id"],
    )
    m = mission(api, tenant, [wp(0, 0, 30, 22), wp(100, 0, 110), wp(200, 0, 118)])
    assert validate(api, tenant, m["id"], base_id=base["id"])["valid"] is True
    r = api.patch(
        f"/api/v1/missions/{m['id']}",
        json={"items": [wp(0, 0, 30, 22), wp(100, 0, 110), wp(600, 0, 100)]},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 200, r.text
    problems = [p for p in validate(api, tenant, m["id"], base_id=base["id"])["problems"]]
    assert problems and problems[0]["segment"] == ["items[1]", "items[2]"]
    assert 99 < problems[0]["value"] < 101  # 100 m of a 500 m leg outside the circle


def test_an_exclusion_circle_in_a_time_window(api, tenant: Tenant):
    m = mission(api, tenant, CROSSING)
    now = datetime.now(UTC)
    later = [
        {
            "start": (now + timedelta(hours=1)).isoformat(),
            "end": (now + timedelta(hours=2)).isoformat(),
        }
    ]
    z = zone(
        api,
        tenant,
        name="event",
        kind="exclusion",
        geometry={"type": "Point", "coordinates": at(100, 10)},
        radius_m=20,
        windows=later,
    )
    assert z["active"] is False
    assert validate(api, tenant, m["id"])["valid"] is True
    report = validate(api, tenant, m["id"], at=(now + timedelta(minutes=90)).isoformat())
    (problem,) = [p for p in report["problems"] if "segment" in p]
    # the chord of a 20 m circle 10 m off the leg: 2 * sqrt(20² - 10²) = 34.6 m
    assert problem["segment"] == ["items[1]", "items[2]"] and problem["value"] == 34.6


def test_the_plans_own_geofence_is_checked(api, tenant: Tenant):
    fence = {
        "version": 2,
        "polygons": [],
        "circles": [
            {
                "inclusion": False,
                "version": 1,
                "circle": {"center": [LAT0, LON0 + 100 * M_LON], "radius": 15},
            }
        ],
    }
    plan = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "QGroundControl",
        "geoFence": fence,
        "rallyPoints": {"version": 2, "points": []},
        "mission": {
            "version": 2,
            "firmwareType": 3,
            "vehicleType": 2,
            "cruiseSpeed": 8,
            "hoverSpeed": 5,
            "plannedHomePosition": [LAT0, LON0, 488],
            "items": [
                {
                    "type": "SimpleItem",
                    "command": c["command"],
                    "frame": 3,
                    "autoContinue": True,
                    "doJumpId": k + 1,
                    "params": [0, 0, 0, None, c["lat"], c["lon"], c["alt"]],
                    "AMSLAltAboveTerrain": None,
                    "Altitude": c["alt"],
                    "AltitudeMode": 1,
                }
                for k, c in enumerate(CROSSING[:3])
            ],
        },
    }
    r = api.post("/api/v1/missions/import", json=plan, headers=tenant.h("operator"))
    assert r.status_code == 201, r.text
    problems = [p for p in validate(api, tenant, r.json()["id"])["problems"] if "segment" in p]
    # out across the circle, and (no RTL in the plan) back across it on the return leg
    assert [p["segment"] for p in problems] == [["items[1]", "items[2]"], ["items[2]", "home"]]
    assert all(p["zone"]["source"] == "plan" and p["value"] == 30.0 for p in problems)


def test_zone_crud_roles_and_organisations(api, tenant: Tenant, superuser_email):
    z = zone(api, tenant, name="a", kind="exclusion", geometry=HOSPITAL, floor_m=10, ceiling_m=60)
    assert z["active"] is True and z["altitude_ref"] == "base" and z["windows"] is None
    assert api.get("/api/v1/airspace/zones", headers=tenant.h("viewer")).json()[0]["id"] == z["id"]
    r = api.post(
        "/api/v1/airspace/zones",
        json={"name": "v", "kind": "exclusion", "geometry": HOSPITAL},
        headers=tenant.h("viewer"),
    )
    assert r.status_code == 403
    other = Tenant(api, superuser_email, "other")
    assert api.get(f"/api/v1/airspace/zones/{z['id']}", headers=other.h()).status_code == 404
    assert api.get("/api/v1/airspace/zones", headers=other.h()).json() == []
    r = api.patch(
        f"/api/v1/airspace/zones/{z['id']}", json={"floor_m": 70}, headers=tenant.h("operator")
    )
    assert r.status_code == 422 and r.json()["error"]["details"][0]["where"] == "ceiling_m"
    assert (
        api.delete(f"/api/v1/airspace/zones/{z['id']}", headers=tenant.h("operator")).status_code
        == 204
    )
    assert api.get(f"/api/v1/airspace/zones/{z['id']}", headers=tenant.h()).status_code == 404


def test_bad_zones_get_a_clear_422(api, tenant: Tenant):
    bowtie = {
        "type": "Polygon",
        "coordinates": [[at(0, 0), at(100, 100), at(100, 0), at(0, 100), at(0, 0)]],
    }
    cases = [
        ({"geometry": bowtie}, "geometry", "intersects itself"),
        ({"geometry": {"type": "Point", "coordinates": at(0, 0)}}, "radius_m", "radius"),
        ({"geometry": HOSPITAL, "radius_m": 5}, "radius_m", "only a Point"),
        (
            {"geometry": {"type": "Point", "coordinates": [8.5, 95]}, "radius_m": 5},
            "geometry.coordinates.lat",
            "latitude",
        ),
    ]
    for extra, where, what in cases:
        r = api.post(
            "/api/v1/airspace/zones",
            json={"name": "z", "kind": "exclusion", **extra},
            headers=tenant.h("operator"),
        )
        assert r.status_code == 422, r.text
        detail = r.json()["error"]["details"][0]
        assert detail["where"] == where and what in detail["what"], detail


def test_import_a_feature_collection(api, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    good = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "geometry": HOSPITAL,
                "properties": {"name": "h", "kind": "exclusion"},
            },
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": at(0, 0)},
                "properties": {
                    "name": "area",
                    "kind": "inclusion",
                    "radius_m": 800,
                    "base_id": base["id"],
                },
            },
        ],
    }
    r = api.post("/api/v1/airspace/zones/import", json=good, headers=tenant.h("operator"))
    assert r.status_code == 201, r.text
    assert [z["name"] for z in r.json()] == ["h", "area"] and r.json()[1]["ceiling_m"] == 120.0
    bad = {
        "type": "FeatureCollection",
        "features": [
            good["features"][0],
            {
                "type": "Feature",
                "geometry": HOSPITAL,
                "properties": {"name": "x", "kind": "no-fly"},
            },
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": at(0, 0)},
                "properties": {"name": "c", "kind": "exclusion"},
            },
            {
                "type": "Feature",
                "geometry": HOSPITAL,
                "properties": {
                    "name": "b",
                    "kind": "inclusion",
                    "base_id": base["id"],
                    "floor_m": 50,
                    "ceiling_m": 40,
                },
            },
        ],
    }
    r = api.post("/api/v1/airspace/zones/import", json=bad, headers=tenant.h("operator"))
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "import_rejected"
    wheres = [d["where"] for d in error["details"]]
    assert wheres == [
        "features[1].properties.kind",
        "features[2].radius_m",
        "features[3].ceiling_m",
    ]
    # all or none: nothing of the refused collection was stored
    assert len(api.get("/api/v1/airspace/zones", headers=tenant.h()).json()) == 2


def test_the_run_check_refuses_a_path_that_a_new_zone_blocks(api, tenant: Tenant):
    m = mission(api, tenant, CROSSING)
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    ids = {"mission_id": m["id"], "uav_id": uav["id"], "base_id": base["id"]}
    run = api.post("/api/v1/runs", json=ids, headers=tenant.h("operator"))
    assert run.status_code == 201, run.text
    zone(api, tenant, name="hospital", kind="exclusion", geometry=HOSPITAL)

    def ended():  # type: ignore[no-untyped-def]
        body = api.get(f"/api/v1/runs/{run.json()['id']}", headers=tenant.h("viewer")).json()
        return body if body["state"] in ("aborted", "failed", "completed") else None

    body = wait_for(ended, 30, what="the run refused by the airspace")
    assert body["state"] == "aborted" and body["cause"] == "airspace", body
    assert "items[1]→items[2]" in body["reason"] and "hospital" in body["reason"]
