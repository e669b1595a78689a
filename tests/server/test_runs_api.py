"""Runs and schedules through the API: validation, one run per asset, abort, timeline, fleet report."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from tests.conftest import Tenant, wait_for


def _setup(api, tenant: Tenant) -> dict:  # type: ignore[no-untyped-def]
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    mission = api.post(
        "/api/v1/missions",
        headers=tenant.h("operator"),
        json={
            "name": "square",
            "items": [
                {"command": 22, "lat": 41.178, "lon": -8.598, "alt": 20},
                {"command": 16, "lat": 41.179, "lon": -8.598, "alt": 20},
                {"command": 20},
            ],
        },
    )
    assert mission.status_code == 201, mission.text
    return {"mission_id": mission.json()["id"], "uav_id": uav["id"], "base_id": base["id"]}


def test_run_validation_and_one_run_per_asset(api, tenant: Tenant):
    ids = _setup(api, tenant)
    swapped = api.post(
        "/api/v1/runs",
        headers=tenant.h("operator"),
        json={**ids, "uav_id": ids["base_id"], "base_id": ids["uav_id"]},
    )
    assert swapped.status_code == 422 and "not a UAV" in swapped.json()["error"]["message"]
    first = api.post("/api/v1/runs", headers=tenant.h("operator"), json=ids)
    assert first.status_code == 201, first.text
    assert first.json()["state"] == "pending" and first.json()["total_steps"] == 8
    second = api.post("/api/v1/runs", headers=tenant.h("operator"), json=ids)
    assert second.status_code == 409 and second.json()["error"]["code"] == "asset_busy"
    assert api.post("/api/v1/runs", headers=tenant.h("viewer"), json=ids).status_code == 403


def test_abort_before_take_off_ends_aborted_with_a_readable_timeline(api, tenant: Tenant):
    ids = _setup(api, tenant)
    run = api.post("/api/v1/runs", headers=tenant.h("operator"), json=ids).json()
    r = api.post(
        f"/api/v1/runs/{run['id']}/abort",
        headers=tenant.h("operator"),
        json={"reason": "fog rolling in"},
    )
    assert r.status_code == 202

    def finished():  # type: ignore[no-untyped-def]
        body = api.get(f"/api/v1/runs/{run['id']}", headers=tenant.h("viewer")).json()
        return body if body["state"] in ("aborted", "failed", "completed") else None

    body = wait_for(finished, 20, what="the aborted run")
    assert body["state"] == "aborted" and body["cause"] == "operator_abort"
    assert body["outcome"] == "aborted" and not body["alert"] and body["issues"] == []
    assert "fog rolling in" in body["reason"] and "nothing had moved" in body["reason"]
    assert body["timeline"][0]["from_state"] == "pending"
    assert body["timeline"][-1]["to_state"] == "aborted"
    assert (
        api.post(
            f"/api/v1/runs/{run['id']}/abort", headers=tenant.h("operator"), json={}
        ).status_code
        == 409
    )
    report = api.get(f"/api/v1/runs/{run['id']}/report", headers=tenant.h("viewer")).json()
    assert report["run"]["id"] == run["id"] and report["flight_time_s"] is None
    fleet = api.get("/api/v1/reports/fleet", headers=tenant.h("viewer")).json()
    assert (
        fleet["runs"] == 1
        and fleet["aborted"] == 1
        and fleet["failures_by_cause"] == {"operator_abort": 1}
    )
    assert fleet["success_rate"] == 0.0
    assert fleet["by_outcome"] == {"aborted": {"operator_abort": 1}}
    assert fleet["completed"] == fleet["completed_with_issues"] == fleet["incomplete"] == 0
    listed = api.get("/api/v1/runs?outcome=aborted", headers=tenant.h("viewer")).json()
    assert [r["id"] for r in listed] == [run["id"]]
    assert api.get("/api/v1/runs?outcome=completed", headers=tenant.h("viewer")).json() == []
    assert api.get("/api/v1/runs?outcome=done", headers=tenant.h("viewer")).status_code == 422


@pytest.mark.slow
def test_unanswered_availability_check_aborts_the_run(api, tenant: Tenant):
    """Assets that never answer: the check step times out (10 s in the test server) and the run is
    aborted, nothing moved."""
    ids = _setup(api, tenant)
    run = api.post("/api/v1/runs", headers=tenant.h("operator"), json=ids).json()

    def finished():  # type: ignore[no-untyped-def]
        body = api.get(f"/api/v1/runs/{run['id']}", headers=tenant.h("viewer")).json()
        return body if body["state"] in ("aborted", "failed", "completed") else None

    body = wait_for(finished, 40, what="the run to end")
    assert body["state"] == "aborted" and body["cause"] == "check_timeout"
    assert "no availability answer from the base and the UAV" in body["reason"]


@pytest.mark.slow
def test_schedules_validate_and_fire_per_policy(api, tenant: Tenant):
    ids = _setup(api, tenant)
    bad = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={**ids, "name": "bad", "kind": "cron", "cron": "61 * * * *"},
    )
    assert bad.status_code == 422 and "cron" in bad.json()["error"]["message"]
    bad_tz = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={**ids, "name": "bad", "kind": "cron", "cron": "0 6 * * *", "timezone": "Mars/Base"},
    )
    assert bad_tz.status_code == 422
    long_ago = (datetime.now(UTC) - timedelta(hours=3)).isoformat()
    skipped = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={**ids, "name": "missed", "kind": "once", "at": long_ago, "missed_policy": "skip"},
    ).json()

    def fired(sid: str):  # type: ignore[no-untyped-def]
        body = api.get(f"/api/v1/schedules/{sid}", headers=tenant.h("viewer")).json()
        return body if body["last_result"] else None

    body = wait_for(lambda: fired(skipped["id"]), 15, what="the missed schedule to be handled")
    assert "skipped" in body["last_result"] and body["last_run_id"] is None and not body["enabled"]
    soon = (datetime.now(UTC) + timedelta(seconds=1)).isoformat()
    once = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={**ids, "name": "soon", "kind": "once", "at": soon},
    ).json()
    body = wait_for(lambda: fired(once["id"]), 15, what="the schedule to fire")
    assert body["last_run_id"] and "started run" in body["last_result"]
    run = api.get(f"/api/v1/runs/{body['last_run_id']}", headers=tenant.h("viewer")).json()
    assert run["schedule_id"] == once["id"]
    runs = api.get("/api/v1/runs", headers=tenant.h("viewer")).json()
    assert [r["id"] for r in runs if r["schedule_id"] == once["id"]] == [body["last_run_id"]]
    assert (
        api.get(f"/api/v1/schedules/{once['id']}", headers=tenant.h("viewer")).json()["enabled"]
        is False
    )


def test_an_interval_below_the_servers_floor_is_refused_naming_it(api, tenant: Tenant):
    ids = _setup(api, tenant)
    body = {**ids, "name": "too often", "kind": "interval"}
    r = api.post("/api/v1/schedules", headers=tenant.h("operator"), json={**body, "interval_s": 59})
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_schedule"
    assert "at least 60 s" in r.json()["error"]["message"]
    r = api.post("/api/v1/schedules", headers=tenant.h("operator"), json={**body, "interval_s": 60})
    assert r.status_code == 201, r.text
