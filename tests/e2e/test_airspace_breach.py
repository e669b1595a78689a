"""Issue 20's breach path end to end: a gust carries the UAV across the fence its autopilot was
given; the autopilot returns it (RTL), the run records the breach, alerts and ends landed on the
base. Every boundary real: server, both daemons, the simulated world over MAVLink and Modbus."""

from __future__ import annotations

import pytest

from sim.vehicle.geo import GeoOrigin
from tests.conftest import Tenant
from tests.e2e.harness import FINAL, platform
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

PAD = (41.178, -8.596, 120.0)
EAST_EDGE_M = 10.0  # the fence runs 10 m east of the northbound leg


def _plan() -> dict:
    """North 90 m and back (RTL), inside a fence whose east edge is 10 m off the leg."""
    o = GeoOrigin(*PAD)

    def at(n: float, e: float) -> list[float]:
        lat, lon, _ = o.to_geodetic(n, e, 0.0)
        return [round(lat, 7), round(lon, 7)]

    def item(k: int, command: int, lat_lon: list[float], alt: float) -> dict:
        return {
            "type": "SimpleItem", "autoContinue": True, "command": command, "doJumpId": k,
            "frame": 3, "params": [0, 0, 0, None, *lat_lon, alt], "Altitude": alt,
            "AltitudeMode": 1, "AMSLAltAboveTerrain": None,
        }  # fmt: skip

    fence = [at(-30, -30), at(-30, EAST_EDGE_M), at(120, EAST_EDGE_M), at(120, -30)]
    return {
        "fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
        "geoFence": {"version": 2, "circles": [],
                     "polygons": [{"inclusion": True, "version": 1, "polygon": fence}]},
        "rallyPoints": {"version": 2, "points": [[*at(-20, -20), 15]]},
        "mission": {
            "version": 2, "firmwareType": 3, "vehicleType": 2, "cruiseSpeed": 8, "hoverSpeed": 5,
            "globalPlanAltitudeMode": 1, "plannedHomePosition": list(PAD),
            "items": [item(1, 22, at(0, 0), 15), item(2, 16, at(90, 0), 15),
                      {**item(3, 20, [0, 0], 0), "frame": 2}],
        },
    }  # fmt: skip


async def test_a_gust_across_the_fence_sends_the_uav_home_and_the_run_records_the_breach(
    live_server, tenant: Tenant, tmp_path
):
    async with platform(live_server.url, tenant, tmp_path, pad=PAD, plan=_plan()) as p:
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying", *FINAL), 90)
        copter = p.copter
        # before take-off the fence and the rally point were on board, read back and enabled
        assert [it.command for it in copter.fence.stored[1]] == [5001] * 4 + [5000]
        assert len(copter.fence.stored[2]) == 1 and copter.param("FENCE_ENABLE") == 1
        await eventually(
            lambda: copter.dyn.state.position[0] > 25 and copter.dyn.state.altitude > 12,
            90,
            "the UAV well out on its northbound leg",
        )
        p.world.weather.gust(peak_mps=28.0, direction_deg=270.0, duration_s=5.0)  # from the west
        await eventually(lambda: copter.fence.breach_count == 1, 30, "the fence breached")
        assert copter.fence.breach_at is not None and copter.fence.breach_at[1] > EAST_EDGE_M
        body = await p.wait_state(run_id, FINAL, 240)
        states = [t["to_state"] for t in body["timeline"]]
        breach = next(t for t in body["timeline"] if t["cause"] == "fence_breach")
        assert breach["from_state"] == "flying" and breach["to_state"] == "landing", states
        assert "geofence" in breach["reason"]
        assert body["alert"] is True  # operators are told
        # back and charging, but the mission was not flown to its end (issue 46): incomplete
        assert body["state"] == "incomplete", (body["reason"], states)
        assert (body["outcome"], body["cause"]) == ("incomplete", "fence_breach"), body["reason"]
        assert states[-4:] == ["confirming", "closing", "charging", "incomplete"]
        assert copter.dyn.state.landed and copter.pad_distance() < 0.1  # on the base's pad
        assert p.world.base.pad_mass_g > 0
        report = (
            await p.api.get(f"/api/v1/runs/{run_id}/report", headers=tenant.h("viewer"))
        ).json()
        (recorded,) = report["airspace_breaches"]
        assert recorded["breach_type"] == "BOUNDARY" and recorded["breach_count"] == 1
        events = await p.uav_events()
        (event,) = [e for e in events if e["name"] == "fence_breach"]
        assert event["severity"] == "critical"
