"""The UAV's agent daemon restarted in flight (a crash, and its service manager starting it again):
the autopilot flies on, and the new agent takes the flight up where it finds it."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from sim.vehicle.constants import AUTO, GUIDED
from tests.conftest import Tenant
from tests.e2e.harness import FINAL, Platform, platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE
from tests.e2e.test_precision_landing import PLND, SEED, SPEED, autopilot_params, watch_while_flying
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane


async def _told(p: Platform, name: str) -> bool:
    return name in [e["name"] for e in await p.uav_events()]


async def test_an_agent_restarted_in_flight_tells_no_new_take_off_and_leaves_the_return_home_be(
    live_server, tenant: Tenant, tmp_path
):
    """Restarted on the survey's legs: the new agent finds the UAV armed in the air (no arming or
    take-off happened then), and reads the mission off the autopilot, so when the run sends it
    home it knows the mission's last item already flies there: no RTL on top of it, which would
    start the return over from its first phase in the middle of the mission's own landing."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await eventually(lambda: _told(p, "took_off"), 60, "the take-off reported")
        first = p.agent
        await p.restart_agent()
        assert p.agent is not first
        await eventually(lambda: p.agent.link.connected, 30, "the new agent connected")
        assert p.copter.armed  # the autopilot flew on without its companion

        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert [t["to_state"] for t in body["timeline"]] == [*WHOLE_SEQUENCE, "completed"]
        names = [e["name"] for e in await p.uav_events()]
        # what happened once is told once
        for once in ("armed", "took_off", "landing", "landed", "disarmed"):
            assert names.count(once) == 1, (once, names)
        commands = (
            await p.api.get(
                f"/api/v1/assets/{p.ids['uav_id']}/commands", headers=tenant.h("viewer")
            )
        ).json()
        (home,) = [c for c in commands if c["name"] == "return_to_base"]
        assert home["status"] == "succeeded", (home["reason"], home["result"])
        assert home["result"]["action"] == "none", home["result"]
        assert "the mission's own return-home" in home["reason"], home


async def test_a_return_home_waiting_for_a_restarted_agent_reads_the_mission_before_it_answers(
    live_server, tenant: Tenant, tmp_path
):
    """The agent is down while the UAV flies on into its mission's RTL item, and a return to the
    base waits for it at the server: the new agent gets it the moment it connects, before its own
    read of the mission has begun (that waits for a HEARTBEAT), and reads the mission first."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await eventually(lambda: _told(p, "took_off"), 60, "the take-off reported")
        await p.stop_agent()
        copter = p.copter
        await eventually(
            lambda: copter.mode == AUTO and copter.mission_current == len(copter.items) - 1,
            60,
            "the UAV on its mission's last item, RTL",
        )
        r = await p.api.post(
            f"/api/v1/assets/{p.ids['uav_id']}/commands",
            json={"name": "return_to_base", "params": {}, "timeout_s": 60},
            headers=tenant.h("operator"),
        )
        assert r.status_code == 202, r.text
        p.start_agent()

        async def answered() -> dict[str, Any] | None:
            got = await p.api.get(f"/api/v1/commands/{r.json()['id']}", headers=tenant.h("viewer"))
            body = dict(got.json())
            return body if body["status"] not in ("queued", "sent", "in_progress") else None

        home = await eventually(answered, 60, "the return to the base answered")
        assert home["status"] == "succeeded", (home["reason"], home["result"])
        assert home["result"]["action"] == "none", home
        assert "the mission's own return-home" in home["reason"], home
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])


# every precision source blind above 6 m: the landing loop starts at 10 m, sees nothing, and the
# agent searches (GUIDED); the search over, it flies over the surveyed pad on its RTK fixed GNSS,
# hands LAND back, and the sources see the pad below 6 m
BLIND_ABOVE_6M = {
    "faults": {source: {"fail_above_m": 6.0} for source in ("pattern", "aruco", "ir")},
    "search": {"max_time_s": 20.0, "max_radius_m": 3.0},
}


@pytest.mark.realtime  # a landing loop through the camera (tests/priority.py)
async def test_an_agent_restarted_in_its_own_search_hands_the_descent_back_and_the_run_lands(
    live_server, tenant: Tenant, tmp_path
):
    """Restarted while it flew the search itself (GUIDED): ArduPilot holds a GUIDED vehicle where
    it is once the setpoints stop, so a new agent that did not know the hover was its
    predecessor's landing would leave it there, and the run would fail by its landing budget with
    the base open. The state file says it was: the new agent hands LAND back, and the landing
    starts afresh (a search again, the RTK fallback, the pad in view low) to the end of the run."""
    async with platform(live_server.url, tenant, tmp_path, speed=4.0, precland=BLIND_ABOVE_6M) as p:
        run_id = await p.start_run()
        first = p.agent.lander
        await eventually(
            lambda: first.takeover and first.takeover.active and p.copter.mode == GUIDED,
            150,
            "the agent searching",
        )
        await p.restart_agent()
        assert p.copter.mode == GUIDED and p.copter.armed  # left hovering

        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        lander = p.agent.lander
        assert lander.record.decision == "resume"
        assert lander.takeover is not None and lander.takeover.path == "rtk-fallback"
        names = [e["name"] for e in await p.uav_events()]
        assert "landing_aborted" not in names and names.count("landed") == 1, names


@pytest.mark.realtime  # a landing loop through the camera (tests/priority.py)
async def test_an_agent_restarted_in_the_middle_of_a_precision_landing_gives_its_parameter_back(
    live_server, tenant: Tenant, tmp_path
):
    """Restarted while the autopilot's LAND descends by the PLND_XY_DIST_MAX it set (5 cm): the
    autopilot keeps the value (ArduPilot saves a PARAM_SET); the new agent reads what its
    predecessor changed from the state file, leaves it under the landing and gives the value from
    before back once the UAV is down: every parameter reads back over MAVLink as before."""
    async with platform(
        live_server.url, tenant, tmp_path, speed=SPEED, seed=SEED, precland={}, habits=PLND
    ) as p:
        before = await autopilot_params(p)
        run_id = await p.start_run()
        first = p.agent.lander
        assert first is not None
        await eventually(
            lambda: first.xy_dist_max == pytest.approx(0.05), 240, "the gate set in the landing"
        )
        await p.restart_agent()
        assert p.copter.flying and p.copter.param("PLND_XY_DIST_MAX") == pytest.approx(0.05)
        flown: list[float] = []
        watch = asyncio.create_task(watch_while_flying(p, flown))
        body = await p.wait_state(run_id, FINAL, 240)
        watch.cancel()
        assert body["state"] in ("completed", "completed_with_issues"), body["reason"]
        assert flown and all(v == pytest.approx(0.05) for v in flown)  # never under the landing
        default = before["PLND_XY_DIST_MAX"]
        await eventually(lambda: p.copter.param("PLND_XY_DIST_MAX") == default, 30, "it back")
        assert await autopilot_params(p) == before
