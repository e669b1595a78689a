"""Fence and rally points on the simulated autopilot through the adapter, over real MAVLink UDP."""

from __future__ import annotations

import pytest

from asset_agent.autopilot import Autopilot, MissionError, items_from_dicts
from asset_agent.autopilot.verify import compare
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.server import VehicleServer
from sim.vehicle.standalone import OpenPad
from tests.polling import eventually


def fence_around(origin: GeoOrigin, half_m: float = 60.0) -> list[dict]:
    """An inclusion square of 2 * half_m around the pad, an exclusion circle, a return point."""
    corners = [(-half_m, -half_m), (-half_m, half_m), (half_m, half_m), (half_m, -half_m)]
    items = []
    for n, e in corners:
        lat, lon, _ = origin.to_geodetic(n, e, 0.0)
        items.append({"command": 5001, "frame": 0, "params": [4, 0, 0, 0], "lat": lat, "lon": lon})
    lat, lon, _ = origin.to_geodetic(30.0, 30.0, 0.0)
    items.append({"command": 5004, "frame": 0, "params": [7.5, 0, 0, 0], "lat": lat, "lon": lon})
    items.append({"command": 5000, "frame": 0, "lat": origin.lat, "lon": origin.lon})
    return items


def rally(origin: GeoOrigin) -> list[dict]:
    lat, lon, _ = origin.to_geodetic(-20.0, 10.0, 0.0)
    return [{"command": 5100, "frame": 3, "lat": lat, "lon": lon, "alt": 15}]


async def test_fence_and_rally_are_uploaded_read_back_and_the_fence_enabled(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    origin = GeoOrigin(*pad.pad_geodetic)
    fence, points = items_from_dicts(fence_around(origin)), items_from_dicts(rally(origin))
    await autopilot.upload_fence(fence, points)  # each read back and compared inside
    copter = vehicle.copter
    assert [it.command for it in copter.fence.stored[1]] == [5001] * 4 + [5004, 5000]
    assert [it.command for it in copter.fence.stored[2]] == [5100]
    back = await autopilot.download_fence()
    assert all(compare(a, b) is None for a, b in zip(fence, back, strict=True))
    assert [
        compare(a, b) for a, b in zip(points, await autopilot.download_rally(), strict=True)
    ] == [None]
    held = await autopilot.enable_fence(alt_max_m=80.0)
    assert held == {
        "FENCE_TYPE": 5.0,
        "FENCE_ALT_MAX": 80.0,
        "FENCE_ACTION": 1.0,
        "FENCE_ENABLE": 1.0,
    }
    assert copter.param("FENCE_ENABLE") == 1 and copter.param("FENCE_ALT_MAX") == 80.0
    # an empty list clears what the autopilot had
    await autopilot.upload_fence([], [])
    assert copter.fence.stored == {1: [], 2: []}


async def test_a_fence_the_autopilot_refuses_names_the_error(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    origin = GeoOrigin(*pad.pad_geodetic)
    bad = fence_around(origin)[:4]
    for item in bad:
        item["params"] = [2, 0, 0, 0]  # a polygon of 2 vertices: AC_PolyFence_loader refuses it
    with pytest.raises(MissionError, match="MAV_MISSION_ERROR"):
        await autopilot.upload_fence(items_from_dicts(bad[:2]), [])
    assert vehicle.copter.fence.stored[1] == []


@pytest.mark.slow
async def test_leaving_the_fence_switches_to_rtl_and_reports_the_breach(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    origin = GeoOrigin(*pad.pad_geodetic)
    await autopilot.upload_fence(items_from_dicts(fence_around(origin, 25.0)), [])
    await autopilot.enable_fence(alt_max_m=None)
    with autopilot.tap(lambda m: m.get_type() == "FENCE_STATUS") as statuses:
        await autopilot.set_mode("GUIDED")
        await autopilot.arm()
        await autopilot.takeoff(8)
        await eventually(lambda: (autopilot.state.alt_rel or 0) > 7, 20, "takeoff altitude")
        autopilot.send_position_ned(60.0, 0.0, -8.0)  # out past the fence's northern edge
        await eventually(lambda: autopilot.state.mode == "RTL", 30, "the fence's RTL")
        copter = vehicle.copter
        assert copter.fence.breach_count == 1 and copter.fence.breach_at is not None
        north = copter.fence.breach_at[0]
        assert 25.0 < north < 27.0, north  # caught as it crossed the northern edge
        breached = []
        while not statuses.empty():
            msg = statuses.get_nowait()
            if msg.breach_status:
                breached.append(msg)
        await eventually(lambda: not statuses.empty(), 5, "FENCE_STATUS")
        while not statuses.empty():
            msg = statuses.get_nowait()
            if msg.breach_status:
                breached.append(msg)
    assert breached and breached[0].breach_type == 3 and breached[0].breach_count == 1
    await eventually(lambda: not autopilot.state.armed, 90, "landed at home and disarmed")
    assert vehicle.copter.pad_distance() < 2.0


async def test_the_runs_upload_carries_the_zones_as_fence_and_rally_enabled_before_take_off(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    """The server's fence for a flight (server/airspace/fence.py) through the agent's real
    upload_mission handler: mission, fence and rally points read back, the fence enabled (RTL)
    before anything arms."""
    import uuid

    from asset_agent.availability import AvailabilityLimits
    from asset_agent.handlers import Handlers
    from assetlink.dispatch import CommandRequest
    from protocol.vocabulary import MissionItem, UploadMission
    from server.airspace.check import ZoneShape
    from server.airspace.fence import build_fence
    from server.missions.items import items_of
    from server.missions.validate import Home

    origin = GeoOrigin(*pad.pad_geodetic)
    home = Home(origin.lat, origin.lon, origin.alt)
    north = origin.to_geodetic(40.0, 0.0, 0.0)
    items = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": 0, "lon": 0, "alt": 12},
        {
            "command": 16,
            "frame": 3,
            "params": [0, 0, 0, None],
            "lat": north[0],
            "lon": north[1],
            "alt": 12,
        },
        {"command": 20, "frame": 2, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0},
    ]
    area = ZoneShape(
        "a",
        "operating area",
        "inclusion",
        center=(origin.lat, origin.lon),
        radius_m=150,
        ceiling_m=120,
    )
    school = origin.to_geodetic(0.0, 80.0, 0.0)
    ring = tuple(
        (p[1], p[0])
        for p in (
            origin.to_geodetic(n, e, 0.0) for n, e in ((-60, 60), (-60, 100), (-20, 100), (-20, 60))
        )
    )
    zones = [area, ZoneShape("s", "school", "exclusion", ring=ring)]
    extras = {"rallyPoints": {"version": 2, "points": [[school[0], school[1] - 0.0005, 14.6]]}}
    fence = build_fence(items_of(items), home, zones, extras)
    assert fence.alt_max_m == 120 and fence.left_to_the_server == []
    command = UploadMission(
        items=tuple(MissionItem.model_validate(i) for i in items),
        fence=tuple(MissionItem.model_validate(i) for i in fence.items),
        rally=tuple(MissionItem.model_validate(i) for i in fence.rally),
        fence_alt_max_m=fence.alt_max_m,
    )
    handlers = Handlers(autopilot, AvailabilityLimits(min_battery_pct=0.0, min_fix_type=0))
    out = [m async for m in handlers.table()[UploadMission](CommandRequest(uuid.uuid4(), command))]
    final = out[-1]
    assert final.status == "succeeded", final
    assert final.data["fence_items"] == 6 and final.data["rally_points"] == 1
    assert "fence enabled" in final.reason
    copter = vehicle.copter
    assert [it.command for it in copter.fence.stored[1]] == [5003, 5002, 5002, 5002, 5002, 5000]
    assert copter.fence.stored[2][0].z == 15.0  # whole metres, as ArduPilot keeps a rally point
    assert copter.param("FENCE_ENABLE") == 1 and copter.param("FENCE_ACTION") == 1
    assert copter.param("FENCE_ALT_MAX") == 120 and not copter.armed  # before take-off


def test_a_new_fence_breach_is_one_event():
    from asset_agent.autopilot.state import UavState
    from asset_agent.events import derive_events

    flying = UavState(
        armed=True,
        landed_state="IN_AIR",
        mode="AUTO",
        lat=41.0,
        lon=-8.0,
        alt_rel=12.0,
        fence_breach_count=0,
    )
    breached = flying.__class__(
        **{
            **flying.__dict__,
            "fence_breached": True,
            "fence_breach_count": 1,
            "fence_breach_type": "BOUNDARY",
            "mode": "RTL",
        }
    )
    (event,) = [e for e in derive_events(flying, breached) if e.kind == "fence_breach"]
    assert event.detail["breach_type"] == "BOUNDARY" and event.detail["mode"] == "RTL"
    assert [e for e in derive_events(breached, breached) if e.kind == "fence_breach"] == []


async def test_an_autopilot_without_the_fence_protocol_keeps_its_mission_and_refuses_a_fence():
    """ArduPilot before 4.0 says no MAV_PROTOCOL_CAPABILITY_MISSION_FENCE: nothing of another
    mission type is sent to it (it could take it for a mission); a fence is refused by name."""
    from asset_agent.autopilot.fence import FenceUnsupported
    from sim.vehicle.copter import CopterConfig
    from sim.vehicle.habits import profile
    from sim.vehicle.server import run_vehicle
    from tests.asset_agent.conftest import fast_config

    config = CopterConfig(seed=5, habits=profile("ardupilot-3.7", boot_s=0.0))
    pad = OpenPad()
    async with run_vehicle(speed=20.0, base=pad, config=config) as vehicle:
        ap = Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}", link_timeout_s=3.0))
        await ap.start()
        try:
            await ap.wait_link(10)
            await ap.upload_fence([], [])  # nothing to enforce: skipped, not an error
            origin = GeoOrigin(*pad.pad_geodetic)
            with pytest.raises(FenceUnsupported, match="MISSION_FENCE"):
                await ap.upload_fence(items_from_dicts(fence_around(origin)), [])
        finally:
            await ap.close()
