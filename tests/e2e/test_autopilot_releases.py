"""Issue 13's acceptance: the QGroundControl plan imported as it is (nulls in it) flies a whole run
against the simulated autopilot behaving as ArduPilot 4.x and as ArduPilot 3.7 (no message
intervals, no extended state, params stored packed), at the plan's speed."""

from __future__ import annotations

import json

import pytest

from sim.vehicle.habits import profile
from tests.conftest import Tenant
from tests.e2e.harness import FINAL, platform
from tests.polling import eventually
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN  # the shared file, byte for byte

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

WHOLE_SEQUENCE = [
    "checking", "opening", "uploading", "flying", "landing", "confirming", "closing", "charging",
]  # fmt: skip


def _plan() -> dict:
    return dict(json.loads(SIMPLE_SQUARE_PLAN))


@pytest.mark.parametrize("release", ["ardupilot-4", "ardupilot-3.7"])
async def test_the_qgc_square_plan_as_is_completes_a_run(
    release: str, live_server, tenant: Tenant, tmp_path
):
    plan = _plan()
    nulls = [i for i in plan["mission"]["items"] if None in i["params"]]
    assert nulls  # as QGroundControl writes it: null yaws
    home = tuple(plan["mission"]["plannedHomePosition"])
    habits = profile(release, boot_s=2.0)
    async with platform(
        live_server.url, tenant, tmp_path, speed=20.0, habits=habits, pad=home, plan=plan
    ) as p:
        run_id = await p.start_run()
        body = await p.wait_state(run_id, FINAL, 240)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert [t["to_state"] for t in body["timeline"]] == [*WHOLE_SEQUENCE, "completed"]
        copter = p.copter
        speeds = [it.param2 for it in copter.items if it.command == 178]
        assert speeds == [plan["mission"]["hoverSpeed"]]  # the plan's 5 m/s went up as an item
        assert copter.guidance.speed == plan["mission"]["hoverSpeed"]  # flown; RTL went at 10
        events = await p.uav_events()
        names = [e["name"] for e in events]
        for name in ("took_off", "mission_finished", "landed"):
            assert name in names, (name, names)
        assert p.agent.autopilot.streams.method == (
            "interval" if release == "ardupilot-4" else "data_stream"
        )
        assert p.agent.autopilot.extended_state_seen == (release == "ardupilot-4")


async def test_an_autopilot_reboot_while_the_base_opens_is_survived(
    live_server, tenant: Tenant, tmp_path
):
    """ArduPilot 3.7 forgets every stream on a reboot and answers no SET_MESSAGE_INTERVAL: the
    agent sees the reboot and asks again, and the run goes on without restarting anything."""
    habits = profile("ardupilot-3.7", boot_s=2.0, reboot_s=1.0)
    async with platform(live_server.url, tenant, tmp_path, speed=20.0, habits=habits) as p:
        ap = p.agent.autopilot
        run_id = await p.start_run()
        await p.wait_state(run_id, ("opening", *FINAL), 60)
        assert p.copter.reboot() == 0  # MAV_RESULT_ACCEPTED: the autopilot restarts
        await eventually(lambda: p.copter.boots == 1, 10, "the autopilot rebooted")
        await eventually(lambda: ap.reboots == 1, 10, "the agent saw the reboot")
        body = await p.wait_state(run_id, FINAL, 240)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert [t["to_state"] for t in body["timeline"]] == [*WHOLE_SEQUENCE, "completed"]
