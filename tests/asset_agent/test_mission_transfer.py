"""Mission upload/download against the simulated autopilot over real MAVLink UDP."""

from __future__ import annotations

import math
import time

import pytest

from asset_agent.autopilot import (
    Autopilot,
    InvalidMissionItem,
    MissionError,
    MissionItem,
    items_from_dicts,
)
from asset_agent.autopilot.verify import compare
from sim.vehicle.server import VehicleServer
from tests.polling import eventually

PAD = (41.1780, -8.5960)


def survey(n: int) -> list[dict]:
    """A takeoff, n - 2 waypoints on a lawnmower grid, and an RTL."""
    items = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, math.nan], "lat": 0, "lon": 0, "alt": 20}
    ]
    for i in range(n - 2):
        items.append({
            "command": 16, "frame": 6, "params": [0.0, 0.5, 0.0, 0.0],
            "lat": PAD[0] + 0.0001 * (i // 10), "lon": PAD[1] + 0.0001 * (i % 10),
            "alt": 20 + i % 5, "autocontinue": True,
        })  # fmt: skip
    items.append({"command": 20, "frame": 2, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0})
    return items


async def test_upload_and_read_back_200_items(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    items = items_from_dicts(survey(200))
    steps: list[tuple[str, int, int]] = []
    await autopilot.upload_mission(items, progress=lambda *p: steps.append(p))  # verified inside
    assert steps[-1] == ("verify", 200, 200) and ("upload", 200, 200) in steps
    assert len(steps) > 20
    back = await autopilot.download_mission()
    assert len(back) == 200
    assert all(compare(a, b) is None for a, b in zip(items, back, strict=True))
    assert len(vehicle.copter.items) == 201  # home + 200
    await eventually(lambda: autopilot.state.mission_total == 200, 5, "MISSION_CURRENT total")


async def test_the_upload_learns_the_plans_id_and_mission_current_carries_it(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    """ArduPilot 4.5+'s MISSION_ACK.opaque_id and MISSION_CURRENT.mission_id, which pymavlink
    2.4.50 does not decode, read from the payload (translate.extension_u32)."""
    await autopilot.upload_mission(items_from_dicts(survey(5)))
    plan = autopilot.mission_watch.opaque_id
    assert plan == vehicle.copter.mission_id != 0
    await eventually(lambda: autopilot.state.mission_id == plan, 5, "MISSION_CURRENT mission_id")


async def test_clear_mission(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    await autopilot.upload_mission(items_from_dicts(survey(5)))
    await autopilot.clear_mission()
    assert await autopilot.download_mission() == []
    assert len(vehicle.copter.items) == 1


async def test_out_of_range_item_is_rejected_with_its_index(autopilot: Autopilot) -> None:
    items = items_from_dicts(survey(10))
    items[5] = MissionItem(command=16, frame=6, x=int(95e7), y=0, z=20)  # latitude 95 degrees
    with pytest.raises(MissionError) as info:
        await autopilot.upload_mission(items)
    assert info.value.index == 5
    assert "MAV_MISSION_INVALID_PARAM5_X" in info.value.reason


async def test_unsupported_item_is_rejected_with_its_index(autopilot: Autopilot) -> None:
    items = items_from_dicts(survey(6))
    items[3] = MissionItem(command=84, frame=3, z=10)  # NAV_VTOL_TAKEOFF: not for a Copter
    with pytest.raises(MissionError) as info:
        await autopilot.upload_mission(items)
    assert info.value.index == 3
    assert "MAV_MISSION_UNSUPPORTED" in info.value.reason


def test_converter_refuses_out_of_range_before_sending() -> None:
    bad = survey(4)
    bad[2]["lat"] = 91.0
    with pytest.raises(InvalidMissionItem) as info:
        items_from_dicts(bad)
    assert info.value.index == 2 and "lat" in info.value.reason


@pytest.mark.parametrize("fault", ["drop_mission", "mute"])
@pytest.mark.slow
async def test_autopilot_silent_mid_upload_gives_a_clear_error(
    autopilot: Autopilot, vehicle: VehicleServer, fault: str
) -> None:
    import asyncio

    items = items_from_dicts(survey(200))
    task = asyncio.create_task(autopilot.upload_mission(items, verify=False))
    copter = vehicle.copter
    await eventually(
        lambda: copter.upload is not None and copter.upload.expected >= 50, 10, "half upload"
    )
    started = time.monotonic()
    if fault == "drop_mission":
        copter.faults.drop_mission = True
    else:
        copter.faults.mute_until = math.inf
    with pytest.raises(MissionError) as info:
        await asyncio.wait_for(task, 15)
    elapsed = time.monotonic() - started
    cfg = autopilot.config
    assert elapsed < (cfg.mission_retries + 2) * cfg.mission_timeout_s + cfg.link_timeout_s
    assert info.value.index is not None and 49 <= info.value.index < 200
    assert "timeout" in info.value.reason or "link lost" in info.value.reason


async def test_a_second_link_cannot_upload_at_the_same_time(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    import asyncio

    from asset_agent.autopilot import Autopilot as Adapter
    from tests.asset_agent.conftest import fast_config

    other = Adapter(fast_config(f"tcp:127.0.0.1:{vehicle.tcp_port}"))
    await other.start()
    try:
        await other.wait_link(10)
        first = asyncio.create_task(
            autopilot.upload_mission(items_from_dicts(survey(200)), verify=False)
        )
        copter = vehicle.copter
        await eventually(
            lambda: copter.upload is not None and copter.upload.expected >= 5, 10, "upload"
        )
        with pytest.raises(MissionError) as info:
            await other.upload_mission(items_from_dicts(survey(3)))
        assert "MAV_MISSION_DENIED" in info.value.reason
        await first
        assert len(copter.items) == 201
    finally:
        await other.close()
