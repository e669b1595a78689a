"""The UAV's agent daemon restarted in flight (a crash, and its service manager starting it again):
the autopilot flies on, and the new agent takes the flight up where it finds it."""

from __future__ import annotations

from typing import Any

import pytest

from tests.conftest import Tenant
from tests.e2e.harness import FINAL, Platform, platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane


async def _events(p: Platform) -> list[dict[str, Any]]:
    r = await p.api.get(f"/api/v1/assets/{p.ids['uav_id']}/events", headers=p.tenant.h("viewer"))
    assert r.status_code == 200, r.text
    return list(r.json())


async def test_an_agent_restarted_in_flight_tells_no_new_take_off_and_leaves_the_return_home_be(
    live_server, tenant: Tenant, tmp_path
):
    """Restarted on the survey's legs: the new agent finds the UAV armed in the air (no arming or
    take-off happened then), and reads the mission off the autopilot, so when the run sends it
    home it knows the mission's last item already flies there: no RTL on top of it, which would
    start the return over from its first phase in the middle of the mission's own landing."""
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)

        async def told_take_off() -> bool:
            return "took_off" in [e["name"] for e in await _events(p)]

        await eventually(told_take_off, 60, "the take-off reported")
        first = p.agent
        await p.restart_agent()
        assert p.agent is not first
        await eventually(lambda: p.agent.link.connected, 30, "the new agent connected")
        assert p.copter.armed  # the autopilot flew on without its companion

        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert [t["to_state"] for t in body["timeline"]] == [*WHOLE_SEQUENCE, "completed"]
        names = [e["name"] for e in await _events(p)]
        # what happened once is told once
        for once in ("armed", "took_off", "landing", "landed", "disarmed"):
            assert names.count(once) == 1, (once, names)
        commands = (
            await p.api.get(
                f"/api/v1/assets/{p.ids['uav_id']}/commands", headers=tenant.h("viewer")
            )
        ).json()
        (home,) = [c for c in commands if c["name"] == "return_to_base"]
        assert home["status"] == "succeeded", home
        assert home["result"]["action"] == "none", home["result"]
        assert "the mission's own return-home" in home["reason"], home
