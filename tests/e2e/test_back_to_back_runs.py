"""Runs back to back on one UAV and base: each flies its own whole mission, whatever the link says
of the last one's end (issue 46: 3 of 6 runs went from flying to "mission finished" within 0.5 s
and ended `completed` with no mission flown)."""

from __future__ import annotations

from datetime import datetime
from typing import Any

import pytest

from sim.vehicle.habits import profile
from tests.conftest import Tenant
from tests.e2e.harness import FINAL, mission_items, platform

pytestmark = pytest.mark.slow  # five whole runs through every process

RUNS = 5
REPEAT = 3  # copies of the old end at each moment


def _t(stamp: str) -> datetime:
    return datetime.fromisoformat(stamp.replace("Z", "+00:00"))


def _window(body: dict[str, Any]) -> tuple[datetime, datetime]:
    """From the run's `flying` transition to its final one."""
    timeline = body["timeline"]
    flying = next(t for t in timeline if t["to_state"] == "flying")
    return _t(flying["at"]), _t(timeline[-1]["at"])


@pytest.mark.parametrize("release", [None, "ardupilot-3.7"], ids=["sim-4.x", "ardupilot-3.7"])
async def test_five_runs_back_to_back_each_fly_their_whole_mission_despite_the_last_ones_end(
    live_server, tenant: Tenant, tmp_path, release: str | None
):
    """The simulated autopilot delivers the previous mission's end (its last MISSION_CURRENT,
    COMPLETE on the old RTL item, and its MISSION_ITEM_REACHED) before each new upload's ack, at
    the arming and right after MISSION_START, three times each (sim/vehicle/stale.py). Every run
    reaches every item of its mission in its own flying window, in order, the RTL item before
    the touchdown, and ends `completed`. The simulator's defaults say which plan they report
    (mission_id) and its state; ArduPilot 3.7 says neither: the demonstrated start alone."""
    habits = None if release is None else profile(release, boot_s=2.0)
    async with platform(live_server.url, tenant, tmp_path, habits=habits) as p:
        stale = p.copter.faults.stale_mission
        stale.enabled, stale.repeat = True, REPEAT
        lat, lon, _ = p.world.base.pad_geodetic
        items = list(range(len(mission_items(lat, lon))))  # takeoff, 3 waypoints, RTL: 0..4
        runs = []
        for n in range(RUNS):
            run_id = await p.start_run()
            body = await p.wait_state(run_id, FINAL, 150)
            assert body["state"] == "completed", (n, body["reason"], body["timeline"])
            runs.append(body)
        events = await p.uav_events()
        numbered: list[list[str]] = []
        for n, body in enumerate(runs):
            start, end = _window(body)
            mine = [e for e in events if start <= _t(e["ts"]) <= end]
            names = [e["name"] for e in mine]
            reached = [e["data"]["index"] for e in mine if e["name"] == "waypoint_reached"]
            assert reached == items, (n, reached, names)
            assert names.count("mission_finished") == 1, (n, names)
            # the mission ended when its RTL item started: after its last waypoint, not at the start
            order = [(e["name"], e["data"].get("index")) for e in mine]
            assert order.index(("waypoint_reached", items[-2])) < order.index(
                ("mission_finished", None)
            ), (n, order)
            last_reached = max(i for i, e in enumerate(names) if e == "waypoint_reached")
            assert last_reached < names.index("landed"), (n, names)  # none after the touchdown
            messages = [e["message"] for e in mine if e["name"] == "waypoint_reached"]
            numbered.append(messages)
        # every mission ended COMPLETE, so runs 2-5 met the old end at three moments, REPEAT
        # copies of two messages each time
        assert stale.replayed == (RUNS - 1) * 3 * REPEAT * 2, stale.status()
        # numbered from 1 as the console numbers mission items: the take-off is "waypoint 1"
        assert all(m[0] == "waypoint 1 reached" for m in numbered), numbered
        spans = [_window(b) for b in runs]
        print("run windows (s):", [round((end - start).total_seconds(), 1) for start, end in spans])
