"""Issue 46 item 3: a mission is checked as flown from its base. The QGroundControl fixture near
Zurich against a base in Porto is refused with the distance and the UAV's reach, by validation,
by `POST /runs` and by a schedule (its cause recorded); the legs to the mission and back count
in the estimate and the airspace."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from server.missions.geometry import haversine_m
from tests.conftest import Tenant
from tests.polling import wait_for
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN

PORTO = (41.178, -8.598)  # the base's surveyed position
FIRST = (47.398742, 8.546594)  # the fixture's first waypoint (items[1]; items[0] is the take-off)
# the default UAV (endurance 1200 s, 20 % reserve) at the plan's speed (a copter's: hoverSpeed
# 5 m/s): (960 s - 10 s take-off - 30 s landing) x 5 m/s / 2
REACH_M = 2300.0


def _zurich_against_porto(api, tenant: Tenant) -> dict[str, str]:  # type: ignore[no-untyped-def]
    base = tenant.create_asset(
        "landing_base", attributes={"latitude": PORTO[0], "longitude": PORTO[1]}
    )
    uav = tenant.create_asset("uav", base_id=base["id"])
    r = api.post(
        "/api/v1/missions/import?name=zurich square",
        content=SIMPLE_SQUARE_PLAN,
        headers={**tenant.h("operator"), "Content-Type": "application/json"},
    )
    assert r.status_code == 201, r.text
    return {"mission_id": r.json()["id"], "uav_id": uav["id"], "base_id": base["id"], **{
        "base_name": base["name"]}}  # fmt: skip


def test_validation_names_the_distance_from_the_base_and_the_uavs_reach(api, tenant: Tenant):
    ids = _zurich_against_porto(api, tenant)
    far = haversine_m(*PORTO, *FIRST)
    assert 1_500_000 < far < 1_550_000
    r = api.post(
        f"/api/v1/missions/{ids['mission_id']}/validate",
        json={"uav_id": ids["uav_id"], "base_id": ids["base_id"]},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 200, r.text
    report = r.json()
    assert report["valid"] is False
    reach = [p for p in report["problems"] if p.get("code") == "out_of_reach"]
    assert len(reach) == 1, report["problems"]
    (problem,) = reach
    assert problem["where"] == "items[1]" and problem["index"] == 1
    assert abs(problem["value"] - far) < 1.0 and problem["limit"] == REACH_M
    assert problem["what"] == (
        f"the mission's first item (items[1]) is {far / 1000:,.1f} km from base "
        f"{ids['base_name']}; the UAV's reach from it is 2.3 km"
    )
    # the endurance counts the legs: out to Zurich and back is over 3,000 km at 5 m/s
    assert report["estimate"]["distance_m"] > 2 * far
    endurance = [p for p in report["problems"] if p.get("code") == "endurance"]
    assert endurance and endurance[0]["value"] > 2 * far / 5
    assert report["uav"]["reach_m"] == REACH_M
    assert report["base"]["id"] == ids["base_id"]
    assert (report["base"]["lat"], report["base"]["lon"]) == PORTO
    assert report["base"]["farthest_m"] >= far - 1.0


def test_a_run_of_a_mission_out_of_reach_is_refused_before_anything_moves(api, tenant: Tenant):
    ids = _zurich_against_porto(api, tenant)
    body = {k: ids[k] for k in ("mission_id", "uav_id", "base_id")}
    r = api.post("/api/v1/runs", json=body, headers=tenant.h("operator"))
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "out_of_reach"
    assert "km from base" in error["message"] and "reach from it is 2.3 km" in error["message"]
    assert [d["code"] for d in error["details"]] == ["out_of_reach", "endurance"]
    detail = error["details"][0]
    assert detail["limit"] == REACH_M
    assert detail["value"] > 1_500_000
    assert api.get("/api/v1/runs", headers=tenant.h("viewer")).json() == []


def test_a_schedules_run_out_of_reach_is_refused_with_its_cause(api, tenant: Tenant):
    ids = _zurich_against_porto(api, tenant)
    body = {k: ids[k] for k in ("mission_id", "uav_id", "base_id")}
    soon = (datetime.now(UTC) + timedelta(seconds=1)).isoformat()
    s = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={**body, "name": "zurich from porto", "kind": "once", "at": soon},
    )
    assert s.status_code == 201, s.text

    def fired():  # type: ignore[no-untyped-def]
        got = api.get(f"/api/v1/schedules/{s.json()['id']}", headers=tenant.h("viewer")).json()
        return got if got["last_result"] else None

    got = wait_for(fired, 15, what="the schedule to fire")
    assert got["last_run_id"] is None
    assert got["last_result"].startswith("could not start the run due")
    assert "km from base" in got["last_result"] and "reach from it is 2.3 km" in got["last_result"]
    assert api.get("/api/v1/runs", headers=tenant.h("viewer")).json() == []


def test_the_legs_from_the_base_count_in_the_estimate_and_the_airspace(api, tenant: Tenant):
    """A base 1.5 km south of a small mission: in reach; the flight there and back lengthens
    the estimate by about 3 km, and a zone on the way there is crossed by the legs there (after the take-off, items[0]→items[1]) and back."""
    home = (41.1900, -8.5980)
    base_at = (home[0] - 1500 / 111_195, home[1])
    base = tenant.create_asset(
        "landing_base", attributes={"latitude": base_at[0], "longitude": base_at[1]}
    )
    uav = tenant.create_asset("uav", base_id=base["id"])
    items = [
        {"command": 22, "lat": 0, "lon": 0, "alt": 20},
        {"command": 16, "lat": home[0] + 0.0005, "lon": home[1], "alt": 20},
        {"command": 16, "lat": home[0] + 0.0005, "lon": home[1] + 0.0005, "alt": 20},
        {"command": 20},
    ]
    m = api.post(
        "/api/v1/missions",
        json={"name": "near", "items": items, "home": {"lat": home[0], "lon": home[1]}},
        headers=tenant.h("operator"),
    )
    assert m.status_code == 201, m.text
    own = m.json()["estimate"]["distance_m"]
    url = f"/api/v1/missions/{m.json()['id']}/validate"
    ok = api.post(
        url, json={"uav_id": uav["id"], "base_id": base["id"]}, headers=tenant.h("operator")
    ).json()
    assert ok["valid"] is True, ok["problems"]
    assert 2 * 1400 < ok["estimate"]["distance_m"] - own < 2 * 1600
    # a keep-out circle halfway between the base and the mission, nowhere near the mission
    mid = ((base_at[0] + home[0]) / 2, home[1])
    zone = api.post(
        "/api/v1/airspace/zones",
        json={
            "name": "halfway",
            "kind": "exclusion",
            "geometry": {"type": "Point", "coordinates": [mid[1], mid[0]]},
            "radius_m": 100,
        },
        headers=tenant.h("operator"),
    )
    assert zone.status_code == 201, zone.text
    report = api.post(
        url, json={"uav_id": uav["id"], "base_id": base["id"]}, headers=tenant.h("operator")
    ).json()
    crossed = [p for p in report["problems"] if p.get("code") == "airspace"]
    # the take-off climbs at the base: the leg to the mission is items[0]→items[1]
    assert {tuple(p["segment"]) for p in crossed} == {
        ("items[0]", "items[1]"),
        ("items[2]", "home"),
    }
    run = api.post(
        "/api/v1/runs",
        json={"mission_id": m.json()["id"], "uav_id": uav["id"], "base_id": base["id"]},
        headers=tenant.h("operator"),
    )
    assert run.status_code == 422 and run.json()["error"]["code"] == "airspace", run.text


async def test_the_battery_reserve_measures_the_way_home_to_the_base(
    api, tenant: Tenant, database_url: str
):
    """A mission planned with its home 2 km north of the base: a UAV hovering over the base
    has only its descent and landing to pay, not a flight back to the mission's home."""
    import asyncio
    import uuid

    from sqlalchemy.ext.asyncio import AsyncSession, create_async_engine

    from server.runs.energy import return_reach
    from server.runs.models import Run

    base = tenant.create_asset(
        "landing_base", attributes={"latitude": PORTO[0], "longitude": PORTO[1]}
    )
    uav = tenant.create_asset("uav", base_id=base["id"])
    home = (PORTO[0] + 2000 / 111_195, PORTO[1])
    items = [
        {"command": 22, "lat": 0, "lon": 0, "alt": 15},
        {"command": 16, "lat": home[0] + 0.0005, "lon": home[1], "alt": 15},
        {"command": 20},
    ]
    m = api.post(
        "/api/v1/missions",
        json={"name": "north", "items": items, "home": {"lat": home[0], "lon": home[1]}},
        headers=tenant.h("operator"),
    )
    assert m.status_code == 201, m.text
    body = {"mission_id": m.json()["id"], "uav_id": uav["id"], "base_id": base["id"]}
    r = await asyncio.to_thread(api.post, "/api/v1/runs", json=body, headers=tenant.h("operator"))
    assert r.status_code == 201, r.text  # 2.1 km out: within the default UAV's 3.7 km reach
    engine = create_async_engine(database_url)
    try:
        async with AsyncSession(engine) as db:
            run = await db.get(Run, uuid.UUID(r.json()["id"]))
            assert run is not None
            over_base = {
                "position.lat": PORTO[0],
                "position.lon": PORTO[1],
                "position.alt_rel_m": 15.0,
                "battery.percent": 90.0,
            }
            reach = await return_reach(db, run, over_base, {})
    finally:
        await engine.dispose()
    # 90 % less the descent (15 m at 1.5 m/s) and the landing (30 s) at 0.1 %/s, less 20 %
    assert reach is not None and not reach.out_of_reach
    assert reach.margin_pct == pytest.approx(90.0 - (10 + 30) * 0.1 - 20.0)


def test_a_run_that_outlasts_the_uavs_endurance_from_the_base_is_refused(api, tenant: Tenant):
    """Every item within reach (224 m for 120 s at 8 m/s), but a 100 s loiter on top: the
    flight from the base and back outlasts the 96 s the UAV may fly."""
    base = tenant.create_asset(
        "landing_base", attributes={"latitude": PORTO[0], "longitude": PORTO[1]}
    )
    uav = tenant.create_asset("uav", base_id=base["id"], attributes={"endurance_s": 120})
    there = (PORTO[0] + 100 / 111_195, PORTO[1])
    items = [
        {"command": 22, "lat": 0, "lon": 0, "alt": 15},
        {"command": 19, "lat": there[0], "lon": there[1], "alt": 15, "params": [100, 0, 0, 0]},
        {"command": 20},
    ]
    m = api.post("/api/v1/missions", json={"name": "loiter", "items": items}, headers=tenant.h())
    assert m.status_code == 201, m.text
    body = {"mission_id": m.json()["id"], "uav_id": uav["id"], "base_id": base["id"]}
    r = api.post("/api/v1/runs", json=body, headers=tenant.h("operator"))
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "beyond_endurance"
    assert "exceeds the UAV's endurance" in error["message"] and "> 96.0" in error["message"]
    assert [d["code"] for d in error["details"]] == ["endurance"]
