"""Issue 46 item 2 end to end: a run's outcome says whether the job was done.

Each run flies through the whole stack (server, base daemon, agent, simulated world); each ends
with the outcome, cause, issues and alert server/runs/outcome.py describes, and the tenant's
fleet report (one run each) counts it so: only a clean completion is a success. The battery
reserve's return is tests/e2e/test_battery_reserve.py; aborts before take-off and in flight are
tests/server/test_runs_api.py and tests/e2e/test_autonomous_run.py.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

import pytest

from tests.conftest import Tenant
from tests.e2e.harness import FINAL, Platform, platform
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane


async def fleet_of(p: Platform) -> dict[str, Any]:
    """The tenant's fleet report (its runs are this test's)."""
    r = await p.api.get("/api/v1/reports/fleet", headers=p.tenant.h("viewer"))
    assert r.status_code == 200, r.text
    return dict(r.json())


def counted_once(fleet: dict[str, Any], outcome: str, cause: str) -> None:
    """One finished run, of `outcome` for `cause`; none a success unless it is `completed`."""
    outcomes = ("completed", "completed_with_issues", "incomplete", "aborted", "failed")
    assert fleet["runs"] == 1 and fleet["in_progress"] == 0, fleet
    assert {o: fleet[o] for o in outcomes} == {o: int(o == outcome) for o in outcomes}, fleet
    assert fleet["success_rate"] == (1.0 if outcome == "completed" else 0.0), fleet
    assert fleet["by_outcome"] == ({} if outcome == "completed" else {outcome: {cause: 1}}), fleet
    assert fleet["failures_by_cause"] == ({} if outcome == "completed" else {cause: 1}), fleet


async def climbed_out(p: Platform, run_id: str) -> None:
    await p.wait_state(run_id, ("flying",), 60)
    await eventually(lambda: (p.agent.autopilot.state.alt_rel or 0) > 10, 60, "the climb-out")


async def listed(p: Platform, outcome: str) -> list[str]:
    r = await p.api.get("/api/v1/runs", params={"outcome": outcome}, headers=p.tenant.h("viewer"))
    assert r.status_code == 200, r.text
    return [run["id"] for run in r.json()]


async def test_charging_refused_completes_with_an_issue_and_an_alert(
    live_server, tenant: Tenant, tmp_path
):
    """The charger faults while the UAV flies: the mission was flown and the UAV is on the pad
    with the base closed, so the job is done, but it cannot charge: `completed_with_issues`
    (`charging_refused`), an alert, and not a success."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await climbed_out(p, run_id)
        p.world.base.charger.fault = True
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert body["outcome"] == "completed_with_issues", body
        assert body["issues"] == ["charging_refused"] and body["cause"] == "charging_refused"
        assert body["alert"] and "charger fault" in body["reason"], body["reason"]
        assert not p.world.base.can_vehicle_leave()  # closed over it
        counted_once(await fleet_of(p), "completed_with_issues", "charging_refused")
        assert await listed(p, "completed_with_issues") == [run_id]
        assert await listed(p, "completed") == []


async def test_landing_off_the_contacts_completes_with_an_issue_and_an_alert(
    live_server, tenant: Tenant, tmp_path
):
    """A 0.3 m GNSS error in flight lands the UAV on the lift (the scale confirms it) but off its
    charging contacts (5 cm): `completed_with_issues` (`landing_off_contacts`) with an alert."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await climbed_out(p, run_id)
        p.copter.gnss.bias_ne_m = (0.3, 0.0)
        body = await p.wait_state(run_id, FINAL, 150)
        assert 0.05 < p.copter.pad_distance() < 0.6, p.copter.pad_distance()
        assert body["outcome"] == "completed_with_issues", (body["reason"], body["timeline"])
        assert body["issues"] == ["landing_off_contacts"], body
        assert body["cause"] == "landing_off_contacts" and body["alert"], body
        assert "contacts not seated" in body["reason"], body["reason"]
        counted_once(await fleet_of(p), "completed_with_issues", "landing_off_contacts")


async def test_an_operators_return_ends_incomplete_without_an_alert(
    live_server, tenant: Tenant, tmp_path
):
    """An operator sends the flying UAV home (a `return_to_base` command of their own, outside
    the run): it lands before its mission's last item, the run carries it through confirming,
    closing and charging, and ends `incomplete` (`operator_return`), not `completed`."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await climbed_out(p, run_id)
        r = await p.api.post(
            f"/api/v1/assets/{p.ids['uav_id']}/commands",
            json={"name": "return_to_base", "params": {}},
            headers=p.tenant.h("operator"),
        )
        assert r.status_code in (201, 202), r.text
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "incomplete" and body["outcome"] == "incomplete", (
            body["reason"],
            body["timeline"],
        )
        assert body["cause"] == "operator_return" and not body["alert"], body
        assert "not flown to its last item" in body["reason"], body["reason"]
        flying = next(t for t in body["timeline"] if t["from_state"] == "flying")
        assert flying["cause"] == "returned_early" and flying["reason"] != "mission finished"
        assert "mission_finished" not in {e["name"] for e in await p.uav_events()}
        assert p.world.base.contacts_seated and not p.world.base.can_vehicle_leave()
        counted_once(await fleet_of(p), "incomplete", "operator_return")


async def test_an_abort_while_landing_ends_aborted_noted_where_it_was_asked(
    live_server, tenant: Tenant, tmp_path
):
    """An operator aborts while the UAV is already landing: it lands, the base closes over it,
    the run ends `aborted` (`operator_abort`, no alert), and its timeline notes the abort in the
    landing step, where it was asked (the console marks that step, not `charging`)."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await p.wait_state(run_id, ("landing", *FINAL), 150)
        r = await p.api.post(
            f"/api/v1/runs/{run_id}/abort",
            json={"reason": "going home"},
            headers=p.tenant.h("operator"),
        )
        assert r.status_code == 202, r.text
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "aborted" and body["outcome"] == "aborted", body["reason"]
        assert body["cause"] == "operator_abort" and not body["alert"], body
        noted = [t for t in body["timeline"] if t["cause"] == "operator_abort"]
        assert noted[0]["from_state"] == noted[0]["to_state"] == "landing", body["timeline"]
        assert "going home" in noted[0]["reason"]
        assert p.world.base.contacts_seated and not p.world.base.can_vehicle_leave()
        counted_once(await fleet_of(p), "aborted", "operator_abort")
        report = (
            await p.api.get(f"/api/v1/runs/{run_id}/report", headers=p.tenant.h("viewer"))
        ).json()
        # take-off to touchdown by the UAV's own events (its clock), not the run's step times
        events = await p.uav_events()
        took_off = next(_at(e) for e in events if e["name"] == "took_off")
        landed = next(_at(e) for e in events if e["name"] == "landed" and _at(e) > took_off)
        assert report["flight_time_s"] == pytest.approx((landed - took_off).total_seconds())


def _at(event: dict[str, Any]) -> datetime:
    return datetime.fromisoformat(event["ts"].replace("Z", "+00:00"))
